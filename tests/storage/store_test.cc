// Stores: multi-epoch round trips, the manifest, interrupted writes, a
// manifest that disagrees with its page files, and concurrent readers.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <chrono>
#include <map>
#include <random>
#include <thread>

#include "storage/checksum.h"
#include "storage/store_reader.h"
#include "storage/store_writer.h"
#include "tests/storage/storage_test_util.h"

namespace octocosm {
namespace {

using storagetest::BlockContent;
using storagetest::ExpectError;
using storagetest::ScratchDirectory;

const nlohmann::json kDataset = {{"simulation", "test"}, {"box_size", 100.0}, {"units", {{"length", "kpc/h"}}}};
const nlohmann::json kSchema = {{"position", "f64x3"}, {"mass", "f64"}};

// What a test store holds: per epoch, key -> (size, point count). Contents
// are BlockContent(epoch, key, size).
using StoreContents = std::vector<std::map<std::uint64_t, std::pair<std::size_t, std::uint64_t>>>;

StoreContents WriteStore(const std::string& directory, std::uint32_t page_size, int epochs, std::size_t blocks,
                         std::uint64_t seed, StoreWriterOptions options = {}) {
  options.page_size = page_size;
  StoreWriter writer(directory, kDataset, kSchema, options);
  std::mt19937_64 random(seed);
  StoreContents contents(epochs);
  std::uint64_t expected_bytes = 0;
  for (int epoch = 0; epoch < epochs; ++epoch) {
    EXPECT_EQ(writer.BeginEpoch(0.25 * (epoch + 1), 3.0 / (epoch + 1) - 1.0), static_cast<std::uint32_t>(epoch));
    std::vector<std::uint64_t> keys;
    while (contents[epoch].size() < blocks) {
      std::uint64_t key = random();
      std::size_t size = random() % 4 == 0 ? 0 : random() % (3 * page_size);
      if (contents[epoch].emplace(key, std::pair{size, random() % 1000}).second) keys.push_back(key);
    }
    for (std::uint64_t key : keys) {  // random order: keys are random
      auto [size, points] = contents[epoch][key];
      writer.AddBlock(key, BlockContent(epoch, key, size), points);
    }
    writer.EndEpoch();
    expected_bytes += storagetest::FileSize(directory + "/" + EpochFileName(static_cast<std::uint32_t>(epoch)));
  }
  writer.Finish();
  EXPECT_EQ(writer.bytes_written(),
            expected_bytes + storagetest::FileSize(directory + "/" + kManifestFileName));
  return contents;
}

void ExpectStoreReadsBack(const StoreReader& store, const StoreContents& contents) {
  const BlockSource& source = store;  // the interface the cache uses
  ASSERT_EQ(store.epoch_count(), contents.size());
  for (std::uint32_t epoch = 0; epoch < contents.size(); ++epoch) {
    EXPECT_EQ(store.block_count(epoch), contents[epoch].size());
    for (const auto& [key, info] : contents[epoch]) {
      BlockId id{epoch, key};
      std::optional<IndexEntry> entry = store.Lookup(id);
      ASSERT_TRUE(entry.has_value());
      EXPECT_EQ(entry->byte_length, info.first);
      EXPECT_EQ(entry->point_count, info.second);
      EXPECT_EQ(source.ReadBlock(id), BlockContent(epoch, key, info.first)) << Hex64(key);
    }
  }
}

TEST(Store, MultiEpochRoundTrip) {
  for (std::uint32_t page_size : {4096u, 65536u}) {
    ScratchDirectory dir;
    StoreContents contents = WriteStore(dir.path(), page_size, 3, 150, page_size);
    StoreReader store = StoreReader::Open(dir.path());
    EXPECT_EQ(store.page_size(), page_size);
    EXPECT_EQ(store.dataset(), kDataset);
    EXPECT_EQ(store.attribute_schema(), kSchema);
    EXPECT_EQ(store.manifest_json()["format"], "octocosm-store");
    ASSERT_EQ(store.epochs().size(), 3u);
    EXPECT_EQ(store.epochs()[1].time, 0.5);
    EXPECT_EQ(store.epochs()[2].redshift, 0.0);
    EXPECT_EQ(store.epochs()[2].file, "epoch-00002.pages");
    ExpectStoreReadsBack(store, contents);

    // Scans per epoch equal the reference.
    for (std::uint32_t epoch = 0; epoch < 3; ++epoch) {
      std::vector<std::uint64_t> got;
      store.Scan(epoch, 0, UINT64_MAX, [&](const IndexEntry& e) { return got.push_back(e.key), true; });
      std::vector<std::uint64_t> want;
      for (const auto& [key, unused] : contents[epoch]) want.push_back(key);
      EXPECT_EQ(got, want);
    }
    // Absent keys and epochs.
    EXPECT_FALSE(store.Lookup({0, 12345}).has_value());
    ExpectError(ErrorKind::kNotFound, [&] { store.ReadBlock({0, 12345}); });
    std::string message = ExpectError(ErrorKind::kNotFound, [&] { store.ReadBlock({3, 1}); });
    EXPECT_NE(message.find("epoch 3"), std::string::npos) << message;
  }
}

// Several processes write one store: each a part of its epochs under their
// final numbers, and the store's writer adopts the parts' page files.
TEST(Store, PartsAdoptedInOrderMakeTheStoreOneWriterMakes) {
  const std::uint32_t page_size = 4096;
  StoreWriterOptions options;
  options.page_size = page_size;
  options.store_id = 0x5eed;
  ScratchDirectory whole_dir, store_dir;
  const StoreContents contents = WriteStore(whole_dir.path(), page_size, 3, 40, 7, options);
  // The same blocks, epoch 0 by the store's writer, epochs 1 and 2 by a part.
  StoreWriter store(store_dir.path(), kDataset, kSchema, options);
  auto write_epoch = [&](StoreWriter& writer, std::uint32_t epoch) {
    EXPECT_EQ(writer.BeginEpoch(0.25 * (epoch + 1), 3.0 / (epoch + 1) - 1.0), epoch);
    for (const auto& [key, info] : contents[epoch]) writer.AddBlock(key, BlockContent(epoch, key, info.first), info.second);
    writer.EndEpoch();
  };
  write_epoch(store, 0);
  const std::string part_dir = store_dir.path() + "/part-1";
  StoreWriterOptions part_options = options;
  part_options.first_epoch = 1;
  std::vector<EpochInfo> part_epochs;
  {
    StoreWriter part(part_dir, nlohmann::json::object(), nlohmann::json::object(), part_options);
    write_epoch(part, 1);
    write_epoch(part, 2);
    ExpectError(ErrorKind::kInvalidArgument, [&] { part.Finish(); });
    part_epochs = part.FinishPart();
  }
  ASSERT_EQ(part_epochs.size(), 2u);
  EXPECT_EQ(part_epochs[0].epoch, 1u);
  EXPECT_TRUE(std::filesystem::exists(part_dir + "/epoch-00002.pages"));  // kept for adoption
  EXPECT_FALSE(std::filesystem::exists(part_dir + "/" + kWriterLockFileName));
  // Out of order, or another store's files: refused, nothing moved.
  std::string message = ExpectError(ErrorKind::kInvalidArgument, [&] {
    store.AdoptEpochs(part_dir, {part_epochs[1]});
  });
  EXPECT_NE(message.find("next epoch is 1"), std::string::npos) << message;
  store.AdoptEpochs(part_dir, part_epochs);
  EXPECT_FALSE(std::filesystem::exists(part_dir + "/epoch-00001.pages"));
  store.Finish();
  std::filesystem::remove(part_dir);

  const StoreReader reader = StoreReader::Open(store_dir.path());
  ExpectStoreReadsBack(reader, contents);
  const StoreReader whole = StoreReader::Open(whole_dir.path());
  EXPECT_EQ(reader.manifest_json(), whole.manifest_json());
  for (std::uint32_t epoch = 0; epoch < 3; ++epoch) {
    const std::string name = "/" + EpochFileName(epoch);
    EXPECT_EQ(storagetest::FileSize(store_dir.path() + name), storagetest::FileSize(whole_dir.path() + name));
  }
}

// A part that another store's id marks, or a store never finished, leaves
// nothing in the store's directory.
TEST(Store, AdoptedEpochsOfAnUnfinishedStoreAreRemoved) {
  ScratchDirectory dir;
  const std::string store_dir = dir.path() + "/store", part_dir = dir.path() + "/part";
  StoreWriterOptions part_options;
  part_options.first_epoch = 0;
  part_options.store_id = 1111;
  std::vector<EpochInfo> part_epochs;
  {
    StoreWriter part(part_dir, nlohmann::json::object(), nlohmann::json::object(), part_options);
    part.BeginEpoch(0, 0);
    part.AddBlock(1, BlockContent(0, 1, 100), 1);
    part.EndEpoch();
    part_epochs = part.FinishPart();
  }
  {
    StoreWriterOptions options;
    options.store_id = 2222;
    StoreWriter store(store_dir, kDataset, kSchema, options);
    const std::string message = ExpectError(ErrorKind::kInvalidArgument, [&] { store.AdoptEpochs(part_dir, part_epochs); });
    EXPECT_NE(message.find("not that of the part"), std::string::npos) << message;
  }
  {
    StoreWriterOptions options;
    options.store_id = 1111;
    StoreWriter store(store_dir, kDataset, kSchema, options);
    store.AdoptEpochs(part_dir, part_epochs);
    EXPECT_TRUE(std::filesystem::exists(store_dir + "/epoch-00000.pages"));
  }
  EXPECT_FALSE(std::filesystem::exists(store_dir));
}

TEST(Store, OpenReadsOnlyManifestAndHeaders) {
  ScratchDirectory dir;
  WriteStore(dir.path(), 4096, 4, 500, 1);
  StoreReader store = StoreReader::Open(dir.path());
  ReaderStats stats = store.stats();
  EXPECT_EQ(stats.header_reads, 4u);
  EXPECT_EQ(stats.index_page_reads, 0u);
  EXPECT_EQ(stats.block_reads, 0u);
  EXPECT_EQ(stats.bytes_read, 4u * 128);
}

TEST(Store, ReadBlockIntoCallerBufferAndCacheControl) {
  ScratchDirectory dir;
  StoreContents contents = WriteStore(dir.path(), 4096, 1, 100, 2);
  StoreReader store = StoreReader::Open(dir.path());
  store.AdviseSequential();
  store.DropCaches();
  Bytes buffer(3 * 4096);
  for (const auto& [key, info] : contents[0]) {
    std::size_t length = store.ReadBlockInto({0, key}, buffer);
    ASSERT_EQ(length, info.first);
    Bytes want = BlockContent(0, key, info.first);
    EXPECT_TRUE(std::equal(want.begin(), want.end(), buffer.begin()));
  }
  EXPECT_EQ(store.stats().block_reads, static_cast<std::uint64_t>(std::count_if(
                                           contents[0].begin(), contents[0].end(),
                                           [](const auto& kv) { return kv.second.first > 0; })));
  ExpectError(ErrorKind::kNotFound, [&] { store.ReadBlockInto({0, 7}, buffer); });
}

TEST(Store, EmptyStoreAndEmptyEpoch) {
  ScratchDirectory dir;
  {
    StoreWriter writer(dir.path(), nlohmann::json::object(), nullptr);
    writer.BeginEpoch(1, 0);
    writer.EndEpoch();
    writer.Finish();
  }
  StoreReader store = StoreReader::Open(dir.path());
  EXPECT_EQ(store.epoch_count(), 1u);
  EXPECT_EQ(store.block_count(0), 0u);
  EXPECT_TRUE(store.attribute_schema().is_null());

  ScratchDirectory none;
  StoreWriter(none.path(), nlohmann::json::object(), nullptr).Finish();
  EXPECT_EQ(StoreReader::Open(none.path()).epoch_count(), 0u);
}

TEST(StoreWriter, RejectsMisuse) {
  ScratchDirectory dir;
  ExpectError(ErrorKind::kInvalidArgument, [&] { StoreWriter(dir.path(), nlohmann::json::array(), nullptr); });
  ExpectError(ErrorKind::kInvalidArgument,
              [&] { StoreWriter(dir.path(), kDataset, kSchema, StoreWriterOptions{1000, 0}); });
  {
    StoreWriter writer(dir.path(), kDataset, kSchema);
    ExpectError(ErrorKind::kInvalidArgument, [&] { writer.AddBlock(1, {}, 0); });
    ExpectError(ErrorKind::kInvalidArgument, [&] { writer.BeginEpoch(std::nan(""), 0); });
    writer.BeginEpoch(0, 0);
    ExpectError(ErrorKind::kInvalidArgument, [&] { writer.BeginEpoch(1, 0); });
    writer.AddBlock(1, {}, 0);
    ExpectError(ErrorKind::kInvalidArgument, [&] { writer.AddBlock(1, {}, 0); });
    ExpectError(ErrorKind::kInvalidArgument, [&] { writer.Finish(); });
    writer.EndEpoch();
    writer.Finish();
    ExpectError(ErrorKind::kInvalidArgument, [&] { writer.BeginEpoch(1, 0); });
  }
  // Never writes over an existing store.
  std::string message = ExpectError(ErrorKind::kInvalidArgument, [&] { StoreWriter(dir.path(), kDataset, kSchema); });
  EXPECT_NE(message.find("already holds store file"), std::string::npos) << message;
  StoreReader::Open(dir.path());  // untouched
}

TEST(StoreWriter, OperatingSystemFailuresAreIoErrors) {
  ScratchDirectory dir;
  std::ofstream(dir.File("plain-file")) << "x";
  // A directory cannot be created under a regular file.
  ExpectError(ErrorKind::kIo, [&] { StoreWriter(dir.File("plain-file/store"), kDataset, kSchema); });
  // The store directory vanishes under an open writer.
  StoreWriter writer(dir.File("store"), kDataset, kSchema);
  std::filesystem::remove_all(dir.File("store"));
  ExpectError(ErrorKind::kIo, [&] { writer.BeginEpoch(0, 0); });
}

// ---------------------------------------------------------------------------
// Interrupted writes never open.

TEST(StoreInterrupted, WriterDestroyedWithoutFinishRemovesItsFiles) {
  ScratchDirectory dir;
  {
    StoreWriter writer(dir.path(), kDataset, kSchema, StoreWriterOptions{4096, 0});
    writer.BeginEpoch(0, 0);
    writer.AddBlock(1, BlockContent(0, 1, 9000), 1);
    writer.EndEpoch();
    writer.BeginEpoch(1, 0);
    writer.AddBlock(2, BlockContent(1, 2, 9000), 1);
    EXPECT_TRUE(std::filesystem::exists(dir.File("epoch-00000.pages")));
    EXPECT_TRUE(std::filesystem::exists(dir.File("epoch-00001.pages.tmp")));
    EXPECT_GT(writer.bytes_written(), 4u * 4096);
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
  std::string message = ExpectError(ErrorKind::kNotFound, [&] { StoreReader::Open(dir.path()); });
  EXPECT_NE(message.find("not an octocosm store"), std::string::npos) << message;
  ExpectError(ErrorKind::kNotFound, [&] { StoreReader::Open(dir.File("no-such-dir")); });
}

TEST(StoreInterrupted, CrashBeforeTheManifest) {
  ScratchDirectory dir;
  WriteStore(dir.path(), 4096, 2, 10, 3);
  std::filesystem::remove(dir.File(kManifestFileName));
  std::string message = ExpectError(ErrorKind::kCorruption, [&] { StoreReader::Open(dir.path()); });
  EXPECT_NE(message.find("no manifest.json: the store was not finished (interrupted write?)"), std::string::npos)
      << message;
}

TEST(StoreInterrupted, LeftoverTemporaryFiles) {
  for (const char* leftover : {"epoch-00002.pages.tmp", "manifest.json.tmp"}) {
    ScratchDirectory dir;
    WriteStore(dir.path(), 4096, 2, 10, 3);
    std::ofstream(dir.File(leftover)) << "partial";
    std::string message = ExpectError(ErrorKind::kCorruption, [&] { StoreReader::Open(dir.path()); });
    EXPECT_NE(message.find(leftover), std::string::npos) << message;
    EXPECT_NE(message.find("interrupted"), std::string::npos) << message;
    // Also when the manifest never made it.
    std::filesystem::remove(dir.File(kManifestFileName));
    message = ExpectError(ErrorKind::kCorruption, [&] { StoreReader::Open(dir.path()); });
    EXPECT_NE(message.find(leftover), std::string::npos) << message;
  }
}

// ---------------------------------------------------------------------------
// The manifest must agree with the page files.

nlohmann::json ReadManifest(const ScratchDirectory& dir) {
  return nlohmann::json::parse(std::ifstream(dir.File(kManifestFileName)));
}

void WriteManifest(const ScratchDirectory& dir, const nlohmann::json& manifest) {
  std::ofstream(dir.File(kManifestFileName), std::ios::trunc) << manifest.dump(2);
}

std::string OpenWithEditedManifest(ErrorKind kind, const std::function<void(nlohmann::json&)>& edit) {
  ScratchDirectory dir;
  WriteStore(dir.path(), 4096, 2, 40, 5);
  nlohmann::json manifest = ReadManifest(dir);
  edit(manifest);
  // Sealed again, so that the checks behind the checksum are reached.
  if (manifest.is_object() && manifest.contains("checksum")) SealManifest(manifest);
  WriteManifest(dir, manifest);
  return ExpectError(kind, [&] { StoreReader::Open(dir.path()); });
}

// Any change to the manifest that its checksum was not recomputed for, even
// in the caller's metadata, which storage/ does not interpret.
TEST(StoreManifest, AChangedManifestFailsItsChecksum) {
  ScratchDirectory dir;
  WriteStore(dir.path(), 4096, 2, 40, 5);
  const nlohmann::json original = ReadManifest(dir);
  const std::vector<std::function<void(nlohmann::json&)>> edits = {
      [](nlohmann::json& m) { m["dataset"]["cube_origin"] = 1.5; },
      [](nlohmann::json& m) { m["epochs"][1]["time"] = 0.25; },
      [](nlohmann::json& m) { m["attribute_schema"] = "other"; },
      [](nlohmann::json& m) { m["unknown_member"] = 1; },
      [](nlohmann::json& m) { m.erase("checksum"); },
  };
  for (std::size_t i = 0; i < edits.size(); ++i) {
    nlohmann::json manifest = original;
    edits[i](manifest);
    WriteManifest(dir, manifest);
    const std::string message = ExpectError(ErrorKind::kCorruption, [&] { StoreReader::Open(dir.path()); });
    EXPECT_NE(message.find(i + 1 < edits.size() ? "checksum mismatch" : "missing member \"checksum\""), std::string::npos)
        << "edit " << i << ": " << message;
    EXPECT_NE(message.find(kManifestFileName), std::string::npos) << message;
  }
  // The layout of the text does not matter, only the JSON value.
  std::ofstream(dir.File(kManifestFileName), std::ios::trunc) << original.dump();
  EXPECT_NO_THROW(StoreReader::Open(dir.path()));
}

TEST(StoreManifest, DisagreementsWithPageFiles) {
  auto expect_mentions = [](const std::string& message, const std::string& text) {
    EXPECT_NE(message.find(text), std::string::npos) << message;
  };
  std::string message = OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["epochs"][1]["block_count"] = 39; });
  expect_mentions(message, "epoch-00001.pages");
  expect_mentions(message, "block count 39");
  message = OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["epochs"][0]["file_size"] = 4096; });
  expect_mentions(message, "file size 4096");
  message = OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["store_id"] = "0000000000000001"; });
  expect_mentions(message, "store id 0x0000000000000001");
  message = OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["page_size"] = 8192; });
  expect_mentions(message, "page size 8192");
  message = OpenWithEditedManifest(ErrorKind::kCorruption,
                                   [](auto& m) { std::swap(m["epochs"][0]["file"], m["epochs"][1]["file"]); });
  expect_mentions(message, "epoch number 0");
  message = OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["epochs"][1]["file"] = "epoch-00009.pages"; });
  expect_mentions(message, "missing page file");
  expect_mentions(message, "epoch-00009.pages");
}

TEST(StoreManifest, MalformedManifests) {
  auto expect_mentions = [](const std::string& message, const std::string& text) {
    EXPECT_NE(message.find(text), std::string::npos) << message;
    EXPECT_NE(message.find("manifest.json"), std::string::npos) << message;
  };
  expect_mentions(OpenWithEditedManifest(ErrorKind::kNotSupported, [](auto& m) { m["format_version"] = 3; }),
                  "store format version 3");
  expect_mentions(OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["format"] = "other"; }), "\"format\"");
  expect_mentions(OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m.erase("epochs"); }),
                  "missing member \"epochs\"");
  expect_mentions(OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["epochs"][1].erase("time"); }),
                  "epochs[1].time");
  expect_mentions(OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["epochs"][0]["block_count"] = -1; }),
                  "epochs[0].block_count");
  expect_mentions(OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["epochs"][1]["epoch"] = 5; }),
                  "numbered 0, 1, 2");
  expect_mentions(OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["epochs"][0]["file"] = "../x"; }),
                  "not a plain file name");
  expect_mentions(OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["store_id"] = 17; }), "store_id");
  expect_mentions(OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m["dataset"] = 3; }), "dataset");
  expect_mentions(OpenWithEditedManifest(ErrorKind::kCorruption, [](auto& m) { m = nlohmann::json::array(); }),
                  "not a JSON object");

  ScratchDirectory dir;
  WriteStore(dir.path(), 4096, 1, 5, 5);
  std::ofstream(dir.File(kManifestFileName), std::ios::trunc) << "{\"format\": ";
  expect_mentions(ExpectError(ErrorKind::kCorruption, [&] { StoreReader::Open(dir.path()); }), "not valid JSON");
  // Valid JSON syntax, but a number no double holds: still the manifest's fault, named.
  std::ofstream(dir.File(kManifestFileName), std::ios::trunc) << "{\"page_size\": 1e400}";
  expect_mentions(ExpectError(ErrorKind::kCorruption, [&] { StoreReader::Open(dir.path()); }), "1e400");
}

TEST(StoreManifest, PageFileFromAnotherStore) {
  ScratchDirectory a;
  ScratchDirectory b;
  WriteStore(a.path(), 4096, 1, 20, 6);
  WriteStore(b.path(), 4096, 1, 20, 6);  // same contents, different store id
  std::filesystem::copy_file(b.File("epoch-00000.pages"), a.File("epoch-00000.pages"),
                             std::filesystem::copy_options::overwrite_existing);
  std::string message = ExpectError(ErrorKind::kCorruption, [&] { StoreReader::Open(a.path()); });
  EXPECT_NE(message.find("another store"), std::string::npos) << message;
}

TEST(StoreManifest, TruncatedPageFile) {
  ScratchDirectory dir;
  WriteStore(dir.path(), 4096, 2, 30, 8);
  const std::string path = dir.File("epoch-00001.pages");
  storagetest::TruncateFile(path, storagetest::FileSize(path) - 4096);
  std::string message = ExpectError(ErrorKind::kCorruption, [&] { StoreReader::Open(dir.path()); });
  EXPECT_NE(message.find("epoch-00001.pages"), std::string::npos) << message;
  EXPECT_NE(message.find("truncated"), std::string::npos) << message;
}

TEST(Store, CorruptBlockErrorNamesFileEpochAndKey) {
  ScratchDirectory dir;
  StoreContents contents = WriteStore(dir.path(), 4096, 2, 30, 9);
  StoreReader store = StoreReader::Open(dir.path());
  for (const auto& [key, info] : contents[1]) {
    if (info.first == 0) continue;
    IndexEntry entry = *store.Lookup({1, key});
    storagetest::FlipByte(dir.File("epoch-00001.pages"), entry.first_page * 4096 + info.first / 2);
    std::string message = ExpectError(ErrorKind::kCorruption, [&] { store.ReadBlock({1, key}); });
    EXPECT_NE(message.find("epoch-00001.pages"), std::string::npos) << message;
    EXPECT_NE(message.find("block " + Hex64(key) + " (epoch 1): checksum mismatch: stored " + Hex64(entry.checksum)),
              std::string::npos)
        << message;
    break;
  }
}

// ---------------------------------------------------------------------------
// Many threads, one reader.

TEST(StoreConcurrency, EightThreadsReadExactData) {
  ScratchDirectory dir;
  StoreContents contents = WriteStore(dir.path(), 4096, 2, 800, 10);
  // A small index cache forces evictions and re-reads under contention.
  StoreReader store = StoreReader::Open(dir.path(), StoreReaderOptions{4});
  std::vector<std::vector<std::pair<std::uint64_t, std::size_t>>> blocks(contents.size());
  for (std::size_t epoch = 0; epoch < contents.size(); ++epoch) {
    for (const auto& [key, info] : contents[epoch]) blocks[epoch].push_back({key, info.first});
  }
  // A fixed number of reads a thread, not a time: the test does the same
  // work however loaded the machine is.
  constexpr int kReadsPerThread = 2000;
  std::atomic<std::uint64_t> reads{0};
  std::atomic<std::uint64_t> failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937_64 random(t);
      Bytes buffer(3 * 4096);
      for (int r = 0; r < kReadsPerThread; ++r) {
        auto epoch = static_cast<std::uint32_t>(random() % blocks.size());
        auto [key, size] = blocks[epoch][random() % blocks[epoch].size()];
        Bytes want = BlockContent(epoch, key, size);
        bool ok = random() % 2 == 0 ? store.ReadBlock({epoch, key}) == want
                                    : store.ReadBlockInto({epoch, key}, buffer) == size &&
                                          std::equal(want.begin(), want.end(), buffer.begin());
        // Absent keys must stay absent under concurrency too.
        ok = ok && !store.Lookup({epoch, key ^ 0x8000000000000000ull}).has_value();
        if (!ok) failures.fetch_add(1);
        reads.fetch_add(1);
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(failures.load(), 0u);
  EXPECT_EQ(reads.load(), 8u * kReadsPerThread);
  ReaderStats stats = store.stats();
  EXPECT_GT(stats.index_page_reads, 0u);
  EXPECT_GT(stats.index_cache_hits, 0u);
}

// The files directly in `directory`, sorted.
std::vector<std::string> Entries(const std::string& directory) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(directory)) names.push_back(entry.path().filename());
  std::sort(names.begin(), names.end());
  return names;
}

void WriteText(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

TEST(StoreWriter, HoldsALockFileWhileWritingAndRemovesItWhenDone) {
  ScratchDirectory dir;
  const std::string lock = dir.File(kWriterLockFileName);
  {
    StoreWriter writer(dir.path(), kDataset, kSchema);
    EXPECT_TRUE(std::filesystem::exists(lock));
    writer.BeginEpoch(0, 0);
    writer.EndEpoch();
    writer.Finish();
    EXPECT_FALSE(std::filesystem::exists(lock));
  }
  EXPECT_EQ(Entries(dir.path()), (std::vector<std::string>{"epoch-00000.pages", "manifest.json"}));

  ScratchDirectory abandoned;
  {
    StoreWriter writer(abandoned.path() + "/store", kDataset, kSchema);
    writer.BeginEpoch(0, 0);
  }
  EXPECT_FALSE(std::filesystem::exists(abandoned.path() + "/store")) << "a directory the writer made goes with it";
}

TEST(StoreWriter, RefusesADirectoryAnotherWriterIsWriting) {
  ScratchDirectory dir;
  StoreWriter first(dir.path(), kDataset, kSchema);
  first.BeginEpoch(0, 0);
  first.EndEpoch();
  const std::string message = ExpectError(ErrorKind::kInvalidArgument, [&] { StoreWriter(dir.path(), kDataset, kSchema); });
  EXPECT_NE(message.find("is being written by another process (pid " + std::to_string(::getpid()) + ")"),
            std::string::npos)
      << message;
  first.Finish();  // the refused writer touched nothing of the first's
  EXPECT_EQ(StoreReader::Open(dir.path()).epoch_count(), 1u);
}

// A writer killed outright (as by kill -9) leaves its files; the next writer
// into the directory finds its lock file unlocked and removes them, and
// nothing else.
TEST(StoreWriter, RemovesWhatAKilledWriterLeft) {
  ScratchDirectory dir;
  const std::string store = dir.File("store");
  std::filesystem::create_directories(store);
  WriteText(store + "/notes.txt", "not the writer's");
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    StoreWriter writer(store, kDataset, kSchema);
    StoreWriter nested(store + "/ids", kDataset, kSchema);
    nested.BeginEpoch(0, 0);
    nested.EndEpoch();
    nested.Finish();
    writer.BeginEpoch(0, 0);
    writer.EndEpoch();
    writer.BeginEpoch(1, 0);  // its page file still under the temporary name
    ::kill(::getpid(), SIGKILL);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  EXPECT_EQ(Entries(store), (std::vector<std::string>{"epoch-00000.pages", "epoch-00001.pages.tmp", "ids",
                                                      kWriterLockFileName, "notes.txt"}));
  ExpectError(ErrorKind::kCorruption, [&] { StoreReader::Open(store); });
  // And what one killed while making its lock file leaves.
  WriteText(store + "/" + kWriterLockFileName + ".Ab12Cd", "pid 1\n");

  {
    StoreWriter writer(store, kDataset, kSchema);
    EXPECT_EQ(Entries(store), (std::vector<std::string>{kWriterLockFileName, "notes.txt"}));
    writer.BeginEpoch(0, 0);
    writer.EndEpoch();
    writer.Finish();
  }
  EXPECT_EQ(StoreReader::Open(store).epoch_count(), 1u);
  EXPECT_EQ(Entries(store), (std::vector<std::string>{"epoch-00000.pages", "manifest.json", "notes.txt"}));
}

TEST(StoreWriter, LeavesStoreFilesAloneThatNoLockFileClaims) {
  ScratchDirectory dir;
  WriteText(dir.File("epoch-00000.pages"), "someone's");
  const std::string message = ExpectError(ErrorKind::kInvalidArgument, [&] { StoreWriter(dir.path(), kDataset, kSchema); });
  EXPECT_NE(message.find("already holds store file epoch-00000.pages"), std::string::npos) << message;
  EXPECT_EQ(Entries(dir.path()), std::vector<std::string>{"epoch-00000.pages"});

  // A finished store whose writer died before removing its lock file: the
  // store stays; only the lock file goes.
  ScratchDirectory finished;
  {
    StoreWriter writer(finished.path(), kDataset, kSchema);
    writer.Finish();
  }
  WriteText(finished.File(kWriterLockFileName), "pid 1\n");
  ExpectError(ErrorKind::kInvalidArgument, [&] { StoreWriter(finished.path(), kDataset, kSchema); });
  EXPECT_EQ(Entries(finished.path()), std::vector<std::string>{"manifest.json"});
  StoreReader::Open(finished.path());
}

TEST(StoreWriter, RemoveUnfinishedStoreKeepsOtherFilesAndFinishedStores) {
  ScratchDirectory dir;
  WriteText(dir.File("epoch-00000.pages"), "x");
  WriteText(dir.File("manifest.json.tmp"), "x");
  WriteText(dir.File(kWriterLockFileName), "pid 1\n");
  WriteText(dir.File("notes.txt"), "x");
  std::filesystem::create_directories(dir.File("ids"));
  WriteText(dir.File("ids/epoch-00000.pages"), "x");
  std::filesystem::create_directories(dir.File("mine"));
  WriteText(dir.File("mine/epoch-00000.pages"), "x");
  WriteText(dir.File("mine/photo.jpg"), "x");
  std::filesystem::create_directories(dir.File("empty"));
  RemoveUnfinishedStore(dir.path());
  EXPECT_EQ(Entries(dir.path()), (std::vector<std::string>{"empty", "mine", "notes.txt"}));
  EXPECT_EQ(Entries(dir.File("mine")), (std::vector<std::string>{"epoch-00000.pages", "photo.jpg"}));

  ScratchDirectory finished;
  {
    StoreWriter writer(finished.path(), kDataset, kSchema);
    writer.Finish();
  }
  RemoveUnfinishedStore(finished.path());
  StoreReader::Open(finished.path());
}

}  // namespace
}  // namespace octocosm
