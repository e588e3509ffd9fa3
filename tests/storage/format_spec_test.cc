// docs/FORMAT.md, checked from the outside: these tests read files the way a
// second implementation would, with offsets and constants copied from the
// document rather than from storage/'s headers, so that the code and the
// document cannot drift apart unnoticed.
#include <gtest/gtest.h>
#include <xxhash.h>

#include <cstdio>
#include <fstream>

#include "storage/block_index_format.h"
#include "storage/page_file_writer.h"
#include "storage/store_writer.h"
#include "tests/storage/storage_test_util.h"

namespace octocosm {
namespace {

using storagetest::BlockContent;
using storagetest::ScratchDirectory;

std::uint64_t U64(const Bytes& b, std::size_t at) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | b[at + i];
  return v;
}
std::uint32_t U32(const Bytes& b, std::size_t at) { return static_cast<std::uint32_t>(U64(b, at) & 0xffffffffu); }

TEST(FormatSpec, ChecksumOfNothing) { EXPECT_EQ(XXH3_64bits(nullptr, 0), 0x2D06800538D394C2ull); }

TEST(FormatSpec, ExampleIndexShapes) {
  // Section 3 of FORMAT.md.
  EXPECT_EQ(LeafCapacity(65536), 1364u);
  EXPECT_EQ(InteriorCapacity(65536), 4094u);
  EXPECT_EQ(ComputeIndexShape(10000000, 65536).pages_per_level, (std::vector<std::uint64_t>{7332, 2, 1}));
  EXPECT_EQ(LeafCapacity(4096), 84u);
  EXPECT_EQ(InteriorCapacity(4096), 254u);
  EXPECT_EQ(ComputeIndexShape(1000000, 4096).pages_per_level, (std::vector<std::uint64_t>{11905, 47, 1}));
  EXPECT_TRUE(ComputeIndexShape(0, 4096).pages_per_level.empty());
  EXPECT_EQ(ComputeIndexShape(84, 4096).pages_per_level, (std::vector<std::uint64_t>{1}));
  EXPECT_EQ(ComputeIndexShape(85, 4096).pages_per_level, (std::vector<std::uint64_t>{2, 1}));
}

TEST(FormatSpec, PageFileAsDocumented) {
  ScratchDirectory dir;
  const std::string path = dir.File("spec.pages");
  const Bytes big = BlockContent(1, 30, 5000);  // two pages
  const Bytes small = BlockContent(1, 10, 7);
  {
    PageFileWriter writer(path, 4096, 0x0102030405060708ull, 9);
    writer.AddBlock(30, big, 300);  // added first: lands first on disk
    writer.AddBlock(20, {}, 0);
    writer.AddBlock(10, small, 100);
    writer.Finish();
  }
  const Bytes file = storagetest::ReadFileBytes(path);
  // Pages: header, 2 for block 30, 1 for block 10, one leaf (the root).
  ASSERT_EQ(file.size(), 5u * 4096);

  // 2.2 The header.
  EXPECT_EQ(std::string(file.begin(), file.begin() + 8), "OCTOPAGE");
  EXPECT_EQ(U32(file, 8), 1u);
  EXPECT_EQ(U32(file, 12), 4096u);
  EXPECT_EQ(U64(file, 16), 0x0102030405060708ull);
  EXPECT_EQ(file[16], 0x08);  // little endian
  EXPECT_EQ(U32(file, 24), 9u);
  EXPECT_EQ(U32(file, 28), 0u);
  EXPECT_EQ(U64(file, 32), 3u);   // block count
  EXPECT_EQ(U64(file, 40), 5u);   // total pages
  EXPECT_EQ(U64(file, 48), 4u);   // index first page
  EXPECT_EQ(U64(file, 56), 1u);   // index pages
  EXPECT_EQ(U64(file, 64), 1u);   // leaf pages
  EXPECT_EQ(U64(file, 72), 4u);   // root
  EXPECT_EQ(U32(file, 80), 1u);   // height
  EXPECT_EQ(U32(file, 84), 128u);
  for (std::size_t i = 88; i < 120; ++i) EXPECT_EQ(file[i], 0) << i;
  EXPECT_EQ(U64(file, 120), XXH3_64bits(file.data(), 120));
  for (std::size_t i = 128; i < 4096; ++i) ASSERT_EQ(file[i], 0) << i;

  // 2.3 Blocks, in the order added, page aligned, zero padded.
  EXPECT_TRUE(std::equal(big.begin(), big.end(), file.begin() + 4096));
  for (std::size_t i = 4096 + big.size(); i < 3 * 4096; ++i) ASSERT_EQ(file[i], 0) << i;
  EXPECT_TRUE(std::equal(small.begin(), small.end(), file.begin() + 3 * 4096));

  // 2.5 The leaf.
  const std::size_t leaf = 4 * 4096;
  EXPECT_EQ(std::string(file.begin() + leaf, file.begin() + leaf + 4), "OCIX");
  EXPECT_EQ(file[leaf + 4], 1);  // leaf
  EXPECT_EQ(file[leaf + 5], 0);  // level
  EXPECT_EQ(U32(file, leaf + 8), 3u);
  EXPECT_EQ(U64(file, leaf + 16), 4u);  // its own page number
  XXH3_state_t* state = XXH3_createState();
  XXH3_64bits_reset(state);
  XXH3_64bits_update(state, file.data() + leaf, 24);
  XXH3_64bits_update(state, file.data() + leaf + 32, 3 * 48);
  EXPECT_EQ(U64(file, leaf + 24), XXH3_64bits_digest(state));
  XXH3_freeState(state);
  struct Want {
    std::uint64_t key, first_page, length, points;
    const Bytes* bytes;
    std::uint32_t pages;
  };
  const Bytes empty;
  const Want want[] = {{10, 3, 7, 100, &small, 1}, {20, 0, 0, 0, &empty, 0}, {30, 1, 5000, 300, &big, 2}};
  for (std::size_t i = 0; i < 3; ++i) {
    const std::size_t e = leaf + 32 + i * 48;
    EXPECT_EQ(U64(file, e), want[i].key);
    EXPECT_EQ(U64(file, e + 8), want[i].first_page);
    EXPECT_EQ(U64(file, e + 16), want[i].length);
    EXPECT_EQ(U64(file, e + 24), want[i].points);
    EXPECT_EQ(U64(file, e + 32), XXH3_64bits(want[i].bytes->data(), want[i].bytes->size()));
    EXPECT_EQ(U32(file, e + 40), want[i].pages);
    EXPECT_EQ(U32(file, e + 44), 0u);
  }
}

TEST(FormatSpec, InteriorPagesAsDocumented) {
  ScratchDirectory dir;
  const std::string path = dir.File("tree.pages");
  {
    PageFileWriter writer(path, 4096, 1, 0);
    for (std::uint64_t key = 0; key < 200; ++key) writer.AddBlock(1000 - key, {}, key);
    writer.Finish();
  }
  const Bytes file = storagetest::ReadFileBytes(path);
  // 200 entries: leaves of 84, 84, 32 at pages 1..3 (no data pages), root at 4.
  ASSERT_EQ(U64(file, 48), 1u);
  ASSERT_EQ(U64(file, 72), 4u);
  ASSERT_EQ(U32(file, 80), 2u);
  const std::size_t root = 4 * 4096;
  EXPECT_EQ(file[root + 4], 2);  // interior
  EXPECT_EQ(file[root + 5], 1);  // level
  ASSERT_EQ(U32(file, root + 8), 3u);
  const std::uint64_t first_keys[] = {801, 885, 969};
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(U64(file, root + 32 + 16 * i), first_keys[i]);
    EXPECT_EQ(U64(file, root + 32 + 16 * i + 8), 1 + i);
    EXPECT_EQ(U64(file, (1 + i) * 4096 + 32), first_keys[i]);  // the leaf's first key
  }
  EXPECT_EQ(U32(file, 3 * 4096 + 8), 32u);
}

TEST(FormatSpec, ManifestAsDocumented) {
  ScratchDirectory dir;
  {
    StoreWriter writer(dir.path(), {{"name", "x"}}, {{"mass", "f64"}}, StoreWriterOptions{8192, 0xabcdef});
    writer.BeginEpoch(0.5, 1.0);
    writer.AddBlock(1, BlockContent(0, 1, 100), 5);
    writer.EndEpoch();
    writer.Finish();
  }
  nlohmann::json manifest = nlohmann::json::parse(std::ifstream(dir.File("manifest.json")));
  EXPECT_EQ(manifest["format"], "octocosm-store");
  EXPECT_EQ(manifest["format_version"], 2);
  // The checksum: XXH3-64 of the compact, key-sorted text of the rest.
  nlohmann::json rest = manifest;
  rest.erase("checksum");
  const std::string text = rest.dump();
  char expected[17];
  std::snprintf(expected, sizeof expected, "%016llx", static_cast<unsigned long long>(XXH3_64bits(text.data(), text.size())));
  EXPECT_EQ(manifest["checksum"], expected);
  EXPECT_EQ(manifest["store_id"], "0000000000abcdef");
  EXPECT_EQ(manifest["page_size"], 8192);
  EXPECT_EQ(manifest["dataset"], (nlohmann::json{{"name", "x"}}));
  EXPECT_EQ(manifest["attribute_schema"], (nlohmann::json{{"mass", "f64"}}));
  ASSERT_EQ(manifest["epochs"].size(), 1u);
  const nlohmann::json& epoch = manifest["epochs"][0];
  EXPECT_EQ(epoch["epoch"], 0);
  EXPECT_EQ(epoch["file"], "epoch-00000.pages");
  EXPECT_EQ(epoch["time"], 0.5);
  EXPECT_EQ(epoch["redshift"], 1.0);
  EXPECT_EQ(epoch["block_count"], 1);
  EXPECT_EQ(epoch["file_size"], 3 * 8192);  // header, one data page, one leaf
  EXPECT_EQ(storagetest::FileSize(dir.File("epoch-00000.pages")), 3u * 8192);
}

}  // namespace
}  // namespace octocosm
