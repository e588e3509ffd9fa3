// Fuzz target: opening a store and reading every block of it, as the query
// and render paths do: the manifest (storage/manifest.h), each page file's
// header and block index (storage/page_file_reader.h), the dataset metadata
// (index/dataset.h), and each block read whole and by columns
// (query/column_reader.h) and decoded (index/block_codec.h).
//
// The input is a little archive of the store's files: a flag byte, then
// sections of a u32 little-endian length and that many bytes (the last one
// may run short): the page file of epoch 0, 1, ..., then manifest.json. The
// page files come first so that mutations near the start, where the driver
// makes half of its own, reach a page-file header and the index rather than
// break the manifest's JSON.
// Flag bit 0 re-seals the manifest, bit 1 the page files (store_fuzz_util.h).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "index/block_codec.h"
#include "index/dataset.h"
#include "index/morton.h"
#include "query/column_reader.h"
#include "storage/coding.h"
#include "storage/manifest.h"
#include "storage/store_writer.h"
#include "tests/fuzz/fuzz_target.h"
#include "tests/fuzz/store_fuzz_util.h"

namespace octocosm::fuzz {
namespace {

inline constexpr std::size_t kMaxPageFiles = 4;
// Blocks read per epoch: enough for the seeds' tallest index, few enough
// that an input claiming millions of tiny blocks stays quick.
inline constexpr std::size_t kMaxBlocksPerEpoch = 128;
inline constexpr std::uint8_t kSealManifest = 1;
inline constexpr std::uint8_t kSealPageFiles = 2;

struct StoreFiles {
  std::uint8_t flags = 0;
  std::vector<std::string> files;  // one page file per epoch, then manifest.json
};

StoreFiles Unpack(const std::uint8_t* data, std::size_t size) {
  StoreFiles store;
  if (size == 0) return store;
  store.flags = data[0];
  std::size_t at = 1;
  while (at + 4 <= size && store.files.size() < kMaxPageFiles + 1) {
    const std::size_t length = std::min<std::size_t>(GetU32(data + at), size - at - 4);
    store.files.emplace_back(reinterpret_cast<const char*>(data + at + 4), length);
    at += 4 + length;
  }
  return store;
}

std::string Pack(const StoreFiles& store) {
  std::string bytes(1, static_cast<char>(store.flags));
  for (const std::string& file : store.files) {
    std::uint8_t length[4];
    PutU32(length, static_cast<std::uint32_t>(file.size()));
    bytes.append(reinterpret_cast<const char*>(length), 4);
    bytes += file;
  }
  return bytes;
}

void ReadEveryBlock(const Dataset& dataset) {
  // The required columns (a block must carry them, wanted or not) and one optional.
  const ColumnSet few = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                        ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kType) | ColumnBit(ColumnId::kId);
  for (std::uint32_t epoch = 0; epoch < dataset.epoch_count(); ++epoch) {
    std::vector<IndexEntry> entries;
    dataset.store().Scan(epoch, 0, ~std::uint64_t{0}, [&](const IndexEntry& entry) {
      entries.push_back(entry);
      return entries.size() < kMaxBlocksPerEpoch;
    });
    for (const IndexEntry& entry : entries) {
      try {
        const auto found = dataset.store().Lookup({epoch, entry.key});
        Require(found.has_value() && *found == entry, "Lookup disagrees with Scan");
        ReadCounters counters;
        const DecodedBlock whole =
            ReadBlockColumns(dataset, epoch, entry, kAllColumns | kClusterLinkColumns, counters);
        Require(whole.points.size() == whole.header.point_count, "a decoded block's weights differ from its count");
        ReadBlockColumns(dataset, epoch, entry, few | dataset.columns(epoch), counters);
        const Bytes subset = ReadBlockSubset(dataset, epoch, entry, few, counters);
        DecodeBlock(subset, few, NodeKey::FromValue(entry.key), dataset.cube(epoch), "fuzz subset");
      } catch (const Error& e) {
        Refused(e);
      }
    }
  }
}

// A store of `epochs` epochs, each with the root and `children` of its
// children (keys in Morton order from octant 0, descending a level every 8),
// written by StoreWriter, then packed.
std::string SeedStore(const std::string& name, std::uint32_t epochs, std::size_t blocks, bool velocity) {
  const std::filesystem::path directory = ScratchDirectory() / ("seed-" + name);
  std::filesystem::remove_all(directory);
  const Cube cube{{-10, -10, -10}, 20, true};
  nlohmann::json dataset = {{"capacity", 64},     {"max_level", 12},      {"epochs", nlohmann::json::array()},
                            {"has_id", true},     {"has_velocity", velocity}};
  {
    StoreWriterOptions options;
    options.store_id = 0x0C70C05;
    StoreWriter writer(directory.string(), nlohmann::json::object(), nlohmann::json::object(), options);
    for (std::uint32_t e = 0; e < epochs; ++e) {
      writer.BeginEpoch(0.5 + e * 0.25, 1 / (0.5 + e * 0.25) - 1);
      std::uint64_t points = 0;
      for (std::size_t b = 0; b < blocks; ++b) {
        // Block 0 the root, then all 8 children, then all 64 grandchildren...
        NodeKey key = NodeKey::Root();
        std::size_t index = b, level_size = 1;
        while (index >= level_size) {
          index -= level_size;
          level_size *= 8;
        }
        for (std::size_t digits = level_size; digits > 1; digits /= 8) key = key.Child(static_cast<int>(index / (digits / 8) % 8));
        const std::size_t n = 1 + (b * 5) % 11;
        const NodePoints node = SeedPoints(key, cube, n, 1 + points, velocity, velocity && b == 0);
        const Bytes block = EncodeBlock(node, key, cube);
        writer.AddBlock(key.value(), block, n);
        points += n;
      }
      writer.EndEpoch();
      dataset["epochs"].push_back({{"cube", {{"origin", cube.origin}, {"size", cube.size}, {"periodic", true}}},
                                   {"points", points},
                                   {"input", {{"time", 0.5 + e * 0.25}, {"cosmological", true}}}});
    }
    if (velocity) {
      dataset["has_velocity_dispersion"] = true;
      dataset["has_shape"] = true;
      dataset["has_cluster_links"] = true;
    }
    writer.SetDataset(dataset);
    writer.Finish();
  }
  StoreFiles store;
  store.flags = kSealManifest | kSealPageFiles;
  for (std::uint32_t e = 0; e < epochs; ++e) store.files.push_back(ReadFileString(directory / EpochFileName(e)));
  store.files.push_back(ReadFileString(directory / kManifestFileName));
  std::filesystem::remove_all(directory);
  return Pack(store);
}

}  // namespace

std::vector<Seed> Seeds(const std::string&) {
  return {{"one-epoch", SeedStore("one-epoch", 1, 3, false)},
          {"two-epochs-velocity", SeedStore("two-epochs-velocity", 2, 9, true)},
          // More blocks than one leaf index page holds at 4 KiB pages: an interior level.
          {"tall-index", SeedStore("tall-index", 1, 90, false)}};
}

}  // namespace octocosm::fuzz

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace octocosm;
  using namespace octocosm::fuzz;
  StoreFiles store = Unpack(data, size);
  if (store.files.empty()) return 0;
  const std::filesystem::path directory = ScratchDirectory() / "store";
  std::filesystem::remove_all(directory);
  std::filesystem::create_directories(directory);
  std::string& manifest = store.files.back();
  if (store.flags & kSealManifest) SealManifestText(manifest);
  WriteFileBytes(directory / kManifestFileName,
                 {reinterpret_cast<const std::uint8_t*>(manifest.data()), manifest.size()});
  for (std::size_t e = 0; e + 1 < store.files.size(); ++e) {
    std::string& file = store.files[e];
    const std::span<std::uint8_t> bytes(reinterpret_cast<std::uint8_t*>(file.data()), file.size());
    if (store.flags & kSealPageFiles) SealPageFile(bytes);
    WriteFileBytes(directory / EpochFileName(static_cast<std::uint32_t>(e)), bytes);
  }
  try {
    ReadEveryBlock(Dataset::Open(directory.string()));
  } catch (const Error& e) {
    Refused(e);
  }
  return 0;
}
