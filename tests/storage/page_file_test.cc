// Page files: round trips, index look-ups and scans against a std::map
// reference, and every kind of damage a page file can suffer.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <algorithm>
#include <csignal>
#include <cstdlib>
#include <map>
#include <numeric>
#include <random>
#include <thread>

#include "storage/block_index_format.h"
#include "storage/checksum.h"
#include "storage/coding.h"
#include "storage/page_file_format.h"
#include "storage/page_file_reader.h"
#include "storage/page_file_writer.h"
#include "tests/storage/storage_test_util.h"

namespace octocosm {
namespace {

using storagetest::BlockContent;
using storagetest::ExpectError;
using storagetest::ScratchDirectory;

constexpr std::uint64_t kStoreId = 0x1234567890abcdefull;

struct Expected {
  Bytes bytes;
  std::uint64_t point_count = 0;
};

// Writes `count` blocks with random keys, random order and sizes from empty
// to several pages; returns what was written.
// With `threads` > 1 the blocks are added from that many threads at once.
std::map<std::uint64_t, Expected> WriteRandomPageFile(const std::string& path, std::uint32_t page_size,
                                                      std::size_t count, std::uint64_t seed,
                                                      std::uint32_t epoch = 0, std::size_t threads = 1) {
  std::mt19937_64 random(seed);
  std::map<std::uint64_t, Expected> expected;
  while (expected.size() < count) {
    std::uint64_t key = random() % (count * 8);
    if (expected.contains(key)) continue;
    std::size_t size = 0;
    switch (random() % 5) {
      case 0: size = 0; break;                                          // empty
      case 1: size = random() % 64; break;                              // tiny
      case 2: size = random() % page_size; break;                       // within a page
      case 3: size = page_size; break;                                  // exactly one page
      default: size = page_size + random() % (3 * page_size); break;    // several pages
    }
    expected[key] = Expected{BlockContent(seed, key, size), random() % 100000};
  }
  // Add in an order unrelated to the keys.
  std::vector<std::uint64_t> order;
  for (const auto& [key, unused] : expected) order.push_back(key);
  std::shuffle(order.begin(), order.end(), random);
  PageFileWriter writer(path, page_size, kStoreId, epoch);
  std::vector<std::thread> adders;
  for (std::size_t t = 0; t < threads; ++t) {
    adders.emplace_back([&, t] {
      for (std::size_t k = t; k < order.size(); k += threads) {
        const Expected& block = expected.at(order[k]);
        writer.AddBlock(order[k], block.bytes, block.point_count);
      }
    });
  }
  for (std::thread& adder : adders) adder.join();
  PageFileWriter::Summary summary = writer.Finish();
  EXPECT_EQ(summary.block_count, count);
  EXPECT_EQ(summary.file_size, storagetest::FileSize(path));
  EXPECT_EQ(writer.bytes_written(), summary.file_size);
  return expected;
}

void ExpectAllBlocksRead(const PageFileReader& reader, const std::map<std::uint64_t, Expected>& expected) {
  for (const auto& [key, want] : expected) {
    std::optional<IndexEntry> entry = reader.Lookup(key);
    ASSERT_TRUE(entry.has_value()) << Hex64(key);
    EXPECT_EQ(entry->byte_length, want.bytes.size());
    EXPECT_EQ(entry->point_count, want.point_count);
    EXPECT_EQ(reader.ReadBlock(*entry), want.bytes) << Hex64(key);
  }
}

// Every block on pages of its own: none overlaps another.
void ExpectNoBlocksOverlap(const PageFileReader& reader) {
  std::vector<std::pair<std::uint64_t, std::uint64_t>> ranges;
  reader.Scan(0, UINT64_MAX, [&](const IndexEntry& entry) {
    if (entry.page_count > 0) ranges.emplace_back(entry.first_page, entry.first_page + entry.page_count);
    return true;
  });
  std::sort(ranges.begin(), ranges.end());
  for (std::size_t i = 1; i < ranges.size(); ++i) EXPECT_LE(ranges[i - 1].second, ranges[i].first);
}

class PageFileRoundTrip : public ::testing::TestWithParam<std::uint32_t> {};

TEST_P(PageFileRoundTrip, RandomBlocksReadBackExactly) {
  const std::uint32_t page_size = GetParam();
  ScratchDirectory dir;
  const std::string path = dir.File("epoch-00003.pages");
  // Enough blocks for a multi-level index at 4 KiB (84 entries per leaf).
  const std::size_t count = page_size == 4096 ? 3000 : page_size == 65536 ? 300 : 40;
  auto expected = WriteRandomPageFile(path, page_size, count, page_size, 3);

  auto reader = PageFileReader::Open(path);
  EXPECT_EQ(reader->block_count(), count);
  EXPECT_EQ(reader->page_size(), page_size);
  EXPECT_EQ(reader->epoch(), 3u);
  EXPECT_EQ(reader->header().store_id, kStoreId);
  ExpectAllBlocksRead(*reader, expected);
  if (page_size == 4096) {
    EXPECT_GE(reader->index_height(), 2u);
  }

  // Keys that are absent: below, between and above the stored ones.
  std::mt19937_64 random(7);
  for (int i = 0; i < 2000; ++i) {
    std::uint64_t key = i < 3 ? std::vector<std::uint64_t>{0, UINT64_MAX, count * 8}[i] : random() % (count * 9);
    if (expected.contains(key)) continue;
    EXPECT_FALSE(reader->Lookup(key).has_value()) << Hex64(key);
    ExpectError(ErrorKind::kNotFound, [&] { reader->ReadBlock(key); });
  }
}

TEST_P(PageFileRoundTrip, RangeScansEqualAStdMap) {
  const std::uint32_t page_size = GetParam();
  ScratchDirectory dir;
  const std::string path = dir.File("scan.pages");
  const std::size_t count = page_size == 4096 ? 2000 : page_size == 65536 ? 400 : 40;
  auto expected = WriteRandomPageFile(path, page_size, count, 99 + page_size);
  auto reader = PageFileReader::Open(path);

  std::mt19937_64 random(3);
  for (int i = 0; i < 200; ++i) {
    std::uint64_t lo = random() % (count * 9);
    std::uint64_t hi = lo + random() % (count * (i % 10 == 0 ? 9 : 1));
    if (i == 0) std::tie(lo, hi) = std::pair<std::uint64_t, std::uint64_t>{0, UINT64_MAX};
    if (i == 1) std::tie(lo, hi) = std::pair<std::uint64_t, std::uint64_t>{UINT64_MAX, UINT64_MAX};
    std::vector<std::uint64_t> want;
    for (auto it = expected.lower_bound(lo); it != expected.end() && it->first <= hi; ++it) want.push_back(it->first);
    std::vector<std::uint64_t> got;
    reader->Scan(lo, hi, [&](const IndexEntry& entry) {
      got.push_back(entry.key);
      EXPECT_EQ(entry.byte_length, expected.at(entry.key).bytes.size());
      return true;
    });
    EXPECT_EQ(got, want) << "[" << lo << ", " << hi << "]";
  }
  // An empty range, and stopping early.
  int visits = 0;
  reader->Scan(10, 5, [&](const IndexEntry&) { return ++visits, true; });
  EXPECT_EQ(visits, 0);
  reader->Scan(0, UINT64_MAX, [&](const IndexEntry&) { return ++visits < 5; });
  EXPECT_EQ(visits, 5);
}

INSTANTIATE_TEST_SUITE_P(PageSizes, PageFileRoundTrip, ::testing::Values(4096u, 65536u, 1048576u));

TEST(PageFileWriter, BlocksAddedFromSeveralThreadsReadBackExactly) {
  ScratchDirectory dir;
  const std::string path = dir.File("threads.pages");
  auto expected = WriteRandomPageFile(path, 4096, 2000, 41, 0, 4);
  auto reader = PageFileReader::Open(path);
  EXPECT_EQ(reader->block_count(), expected.size());
  ExpectAllBlocksRead(*reader, expected);
  ExpectNoBlocksOverlap(*reader);
}

// A write that fails (here: past the file size limit, EFBIG) is an I/O error,
// and the writer then refuses to finish a file with a block it could not
// write. Run in a child process (the limit would hold for the whole test
// program); exits 0 when all is as expected.
[[noreturn]] void WriteBeyondTheFileSizeLimit(const std::string& path) {
  std::signal(SIGXFSZ, SIG_IGN);
  rlimit limit{};
  limit.rlim_cur = limit.rlim_max = 1 << 20;
  if (::setrlimit(RLIMIT_FSIZE, &limit) != 0) std::_Exit(10);
  PageFileWriter writer(path, 4096, kStoreId, 0);
  writer.AddBlock(1, BlockContent(1, 1, 1000), 1);
  // A direct write fails after AddBlock has returned, and Finish reports it;
  // a write through the page cache fails inside AddBlock, and Finish refuses.
  bool failed_in_add = false;
  try {
    writer.AddBlock(2, BlockContent(1, 2, 2 << 20), 1);
  } catch (const Error& error) {
    if (error.kind() != ErrorKind::kIo) std::_Exit(12);
    failed_in_add = true;
  }
  try {
    writer.Finish();
    std::_Exit(13);
  } catch (const Error& error) {
    const std::string what = error.what();
    if (error.kind() != ErrorKind::kIo || what.find(writer.temporary_path()) == std::string::npos) std::_Exit(14);
    if (failed_in_add && what.find("earlier block write failed") == std::string::npos) std::_Exit(15);
  }
  try {
    writer.AddBlock(3, BlockContent(1, 3, 10), 1);
    std::_Exit(16);
  } catch (const Error& error) {
    const bool refused = error.kind() == ErrorKind::kIo &&
                         std::string(error.what()).find("earlier block write failed") != std::string::npos;
    std::_Exit(refused ? 0 : 17);
  }
}

TEST(PageFileWriter, AFailedBlockWriteRefusesFinish) {
  ScratchDirectory dir;
  EXPECT_EXIT(WriteBeyondTheFileSizeLimit(dir.File("limited.pages")), ::testing::ExitedWithCode(0), "");
}

TEST(PageFileWriter, RejectsDuplicateKeysAndBadPageSizes) {
  ScratchDirectory dir;
  PageFileWriter writer(dir.File("dup.pages"), 4096, kStoreId, 0);
  Bytes bytes = BlockContent(1, 5, 100);
  writer.AddBlock(5, bytes, 1);
  std::string message = ExpectError(ErrorKind::kInvalidArgument, [&] { writer.AddBlock(5, bytes, 1); });
  EXPECT_NE(message.find("0x0000000000000005"), std::string::npos) << message;
  writer.AddBlock(6, bytes, 1);  // still usable
  EXPECT_EQ(writer.Finish().block_count, 2u);

  for (std::uint32_t bad : {0u, 2048u, 5000u, 32u * 1024 * 1024}) {
    ExpectError(ErrorKind::kInvalidArgument, [&] { PageFileWriter(dir.File("bad.pages"), bad, kStoreId, 0); });
  }
}

// Blocks of keys [first_key, first_key + count), sizes from empty to several
// pages, written to a page file of their own.
std::map<std::uint64_t, Expected> WriteKeyRange(const std::string& path, std::uint32_t page_size,
                                                std::uint64_t first_key, std::size_t count, std::uint32_t epoch = 0) {
  std::map<std::uint64_t, Expected> blocks;
  PageFileWriter writer(path, page_size, kStoreId, epoch);
  for (std::uint64_t key = first_key; key < first_key + count; ++key) {
    const std::size_t size = key % 7 == 0 ? 0 : (key * 2654435761u) % (3 * page_size);
    blocks[key] = Expected{BlockContent(first_key, key, size), key * 3};
    writer.AddBlock(key, blocks[key].bytes, blocks[key].point_count);
  }
  writer.Finish();
  return blocks;
}

TEST(PageFileWriter, BlocksOfOtherPageFilesCopiedInAsTheyAreReadBackExactly) {
  ScratchDirectory dir;
  const auto first = WriteKeyRange(dir.File("first.pages"), 4096, 1000, 300);
  const auto second = WriteKeyRange(dir.File("second.pages"), 4096, 5000, 200);
  const auto empty = WriteKeyRange(dir.File("empty.pages"), 4096, 9000, 0);
  std::map<std::uint64_t, Expected> expected;
  PageFileWriter writer(dir.File("whole.pages"), 4096, kStoreId, 0);
  auto add = [&](std::uint64_t key, std::size_t size) {
    expected[key] = Expected{BlockContent(7, key, size), key};
    writer.AddBlock(key, expected[key].bytes, key);
  };
  add(1, 5000);
  add(2, 0);
  const std::uint64_t first_at = writer.ReserveBlocksOf(*PageFileReader::Open(dir.File("first.pages")));
  add(3, 100);
  const std::uint64_t empty_at = writer.ReserveBlocksOf(*PageFileReader::Open(dir.File("empty.pages")));
  const std::uint64_t second_at = writer.ReserveBlocksOf(*PageFileReader::Open(dir.File("second.pages")));
  add(4, 9000);
  EXPECT_EQ(first_at % 4096, 0u);
  EXPECT_LT(first_at, second_at);
  EXPECT_EQ(empty_at, second_at);
  // Copied while the writer's own blocks are still being written, from other
  // threads, as other processes would.
  std::thread copy_first([&] { CopyBlockPages(dir.File("first.pages"), writer.temporary_path(), first_at); });
  std::thread copy_second([&] { CopyBlockPages(dir.File("second.pages"), writer.temporary_path(), second_at); });
  CopyBlockPages(dir.File("empty.pages"), writer.temporary_path(), empty_at);
  add(5, 70000);
  copy_first.join();
  copy_second.join();
  EXPECT_EQ(writer.Finish().block_count, 5u + first.size() + second.size());
  expected.insert(first.begin(), first.end());
  expected.insert(second.begin(), second.end());
  const auto reader = PageFileReader::Open(dir.File("whole.pages"));
  EXPECT_EQ(reader->block_count(), expected.size());
  ExpectAllBlocksRead(*reader, expected);
  ExpectNoBlocksOverlap(*reader);
}

TEST(PageFileWriter, RefusesBlocksOfAnotherPageSizeEpochStoreOrWithKeysItHas) {
  ScratchDirectory dir;
  WriteKeyRange(dir.File("big_pages.pages"), 8192, 100, 10);
  WriteKeyRange(dir.File("epoch_1.pages"), 4096, 200, 10, /*epoch=*/1);
  WriteKeyRange(dir.File("overlap.pages"), 4096, 300, 10);
  {
    PageFileWriter other_store(dir.File("other_store.pages"), 4096, kStoreId + 1, 0);
    other_store.AddBlock(400, BlockContent(1, 400, 10), 1);
    other_store.Finish();
  }
  PageFileWriter writer(dir.File("whole.pages"), 4096, kStoreId, 0);
  writer.AddBlock(305, BlockContent(1, 305, 10), 1);
  for (const char* name : {"big_pages.pages", "epoch_1.pages", "overlap.pages", "other_store.pages"}) {
    const std::string message = ExpectError(ErrorKind::kInvalidArgument, [&] {
      writer.ReserveBlocksOf(*PageFileReader::Open(dir.File(name)));
    });
    EXPECT_NE(message.find(name), std::string::npos) << message;
  }
  // Nothing of a refused file was added.
  writer.AddBlock(301, BlockContent(1, 301, 10), 1);
  EXPECT_EQ(writer.Finish().block_count, 2u);
}

TEST(PageFileWriter, AbandonedWriterLeavesNoFiles) {
  ScratchDirectory dir;
  {
    PageFileWriter writer(dir.File("gone.pages"), 4096, kStoreId, 0);
    writer.AddBlock(1, BlockContent(1, 1, 10000), 3);
    EXPECT_TRUE(std::filesystem::exists(dir.File("gone.pages.tmp")));
    EXPECT_FALSE(std::filesystem::exists(dir.File("gone.pages")));
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

TEST(PageFile, EmptyFileHasNoIndex) {
  ScratchDirectory dir;
  const std::string path = dir.File("empty.pages");
  PageFileWriter writer(path, 4096, kStoreId, 0);
  EXPECT_EQ(writer.Finish().file_size, 4096u);
  auto reader = PageFileReader::Open(path);
  EXPECT_EQ(reader->block_count(), 0u);
  EXPECT_EQ(reader->index_height(), 0u);
  EXPECT_FALSE(reader->Lookup(0).has_value());
  int visits = 0;
  reader->Scan(0, UINT64_MAX, [&](const IndexEntry&) { return ++visits, true; });
  EXPECT_EQ(visits, 0);
}

TEST(PageFile, ReadBlockIntoCallerBuffer) {
  ScratchDirectory dir;
  const std::string path = dir.File("into.pages");
  auto expected = WriteRandomPageFile(path, 4096, 50, 11);
  auto reader = PageFileReader::Open(path);
  Bytes buffer(4 * 4096 + 100, 0xee);
  for (const auto& [key, want] : expected) {
    IndexEntry entry = *reader->Lookup(key);
    reader->ReadBlockInto(entry, buffer);
    EXPECT_TRUE(std::equal(want.bytes.begin(), want.bytes.end(), buffer.begin()));
    if (!want.bytes.empty()) {
      Bytes small(want.bytes.size() - 1);
      ExpectError(ErrorKind::kInvalidArgument, [&] { reader->ReadBlockInto(entry, small); });
    }
  }
}

TEST(PageFile, ReadBlocksIntoReadsSeveralInFileOrderAndVerifiesEach) {
  ScratchDirectory dir;
  const std::string path = dir.File("several.pages");
  auto expected = WriteRandomPageFile(path, 4096, 60, 12);
  auto reader = PageFileReader::Open(path);
  std::vector<IndexEntry> entries;
  reader->Scan(0, UINT64_MAX, [&](const IndexEntry& entry) { return entries.push_back(entry), true; });
  std::sort(entries.begin(), entries.end(),
            [](const IndexEntry& a, const IndexEntry& b) { return a.first_page < b.first_page; });
  // Every other block, so that the reads have gaps between them.
  std::vector<IndexEntry> wanted;
  for (std::size_t i = 0; i < entries.size(); i += 2) wanted.push_back(entries[i]);
  std::vector<Bytes> buffers(wanted.size());
  std::vector<std::span<std::uint8_t>> outs;
  for (std::size_t i = 0; i < wanted.size(); ++i) {
    buffers[i].assign(static_cast<std::size_t>(wanted[i].byte_length) + 7, 0xee);
    outs.emplace_back(buffers[i]);
  }
  reader->ReadBlocksInto(wanted, outs);
  for (std::size_t i = 0; i < wanted.size(); ++i) {
    const Bytes& want = expected.at(wanted[i].key).bytes;
    EXPECT_TRUE(std::equal(want.begin(), want.end(), buffers[i].begin())) << Hex64(wanted[i].key);
  }
  EXPECT_EQ(reader->stats().block_reads, wanted.size());

  // Out of the file's order: refused.
  std::vector<IndexEntry> reversed(wanted.rbegin(), wanted.rend());
  std::vector<std::span<std::uint8_t>> reversed_outs(outs.rbegin(), outs.rend());
  ExpectError(ErrorKind::kInvalidArgument, [&] { reader->ReadBlocksInto(reversed, reversed_outs); });

  // A damaged block among them is named.
  const auto damaged = std::find_if(wanted.begin() + 1, wanted.end(), [](const IndexEntry& e) { return e.byte_length > 0; });
  ASSERT_NE(damaged, wanted.end());
  storagetest::FlipByte(path, reader->BlockOffset(*damaged), 0x10);
  auto reopened = PageFileReader::Open(path);
  const std::string message = ExpectError(ErrorKind::kCorruption, [&] { reopened->ReadBlocksInto(wanted, outs); });
  EXPECT_NE(message.find("block " + Hex64(damaged->key)), std::string::npos) << message;
  EXPECT_NE(message.find("checksum mismatch"), std::string::npos) << message;
}

// ---------------------------------------------------------------------------
// Damage. Each test writes a small file, damages it, and checks the error.

struct SmallFile {
  ScratchDirectory dir;
  std::string path;
  std::map<std::uint64_t, Expected> expected;
  std::uint32_t page_size = 4096;

  explicit SmallFile(std::size_t count = 400, std::uint64_t seed = 5) {
    path = dir.File("epoch-00000.pages");
    expected = WriteRandomPageFile(path, page_size, count, seed);
  }

  // Looks up every key and scans the index; returns normally only if all of
  // it was right.
  void ReadIndex() const {
    auto reader = PageFileReader::Open(path);
    for (const auto& [key, want] : expected) {
      std::optional<IndexEntry> entry = reader->Lookup(key);
      if (!entry || entry->byte_length != want.bytes.size()) throw std::logic_error("wrong entry for " + Hex64(key));
    }
    std::size_t scanned = 0;
    reader->Scan(0, UINT64_MAX, [&](const IndexEntry&) { return ++scanned, true; });
    if (scanned != expected.size()) throw std::logic_error("scan lost entries");
  }

  // Reads everything; returns normally only if all of it was right.
  void ReadEverything() const {
    auto reader = PageFileReader::Open(path);
    for (const auto& [key, want] : expected) {
      std::optional<IndexEntry> entry = reader->Lookup(key);
      if (!entry) throw Error::NotFound("lost " + Hex64(key));
      if (reader->ReadBlock(*entry) != want.bytes) throw std::logic_error("wrong bytes returned for " + Hex64(key));
    }
    std::size_t scanned = 0;
    reader->Scan(0, UINT64_MAX, [&](const IndexEntry&) { return ++scanned, true; });
    if (scanned != expected.size()) throw std::logic_error("scan lost entries");
  }
};

TEST(PageFileCorruption, EveryByteOfASmallBlockIsCovered) {
  ScratchDirectory dir;
  const std::string path = dir.File("epoch-00000.pages");
  const Bytes block = BlockContent(1, 0xabc, 300);
  {
    PageFileWriter writer(path, 4096, kStoreId, 0);
    writer.AddBlock(0xabc, block, 1);
    writer.Finish();
  }
  for (std::size_t i = 0; i < block.size(); ++i) {
    storagetest::FlipByte(path, 4096 + i, static_cast<std::uint8_t>(1u << (i % 8)));
    auto reader = PageFileReader::Open(path);
    std::string message = ExpectError(ErrorKind::kCorruption, [&] { reader->ReadBlock(0xabc); });
    EXPECT_NE(message.find("block 0x0000000000000abc (epoch 0)"), std::string::npos) << message;
    EXPECT_NE(message.find("checksum mismatch: stored 0x"), std::string::npos) << message;
    EXPECT_NE(message.find("epoch-00000.pages"), std::string::npos) << message;
    storagetest::FlipByte(path, 4096 + i, static_cast<std::uint8_t>(1u << (i % 8)));
  }
  EXPECT_EQ(PageFileReader::Open(path)->ReadBlock(0xabc), block);
}

TEST(PageFileCorruption, RandomBytesOfBigBlocks) {
  SmallFile file(60, 17);
  auto reader = PageFileReader::Open(file.path);
  std::mt19937_64 random(4);
  int checked = 0;
  for (const auto& [key, want] : file.expected) {
    if (want.bytes.size() < 4096) continue;
    IndexEntry entry = *reader->Lookup(key);
    for (int i = 0; i < 8; ++i) {
      std::uint64_t offset = entry.first_page * 4096 + random() % want.bytes.size();
      storagetest::FlipByte(file.path, offset, 0x80);
      std::string message = ExpectError(ErrorKind::kCorruption, [&] { reader->ReadBlock(*reader->Lookup(key)); });
      EXPECT_NE(message.find(Hex64(key)), std::string::npos) << message;
      storagetest::FlipByte(file.path, offset, 0x80);
      ++checked;
    }
    EXPECT_EQ(reader->ReadBlock(entry), want.bytes);
  }
  EXPECT_GT(checked, 50);
}

TEST(PageFileCorruption, PaddingAfterABlockIsNotRead) {
  // Padding is outside every checksum by design (a block is read as exactly
  // its bytes, one range request); damage there must not fail a read.
  SmallFile file(30, 21);
  auto reader = PageFileReader::Open(file.path);
  for (const auto& [key, want] : file.expected) {
    if (want.bytes.empty() || want.bytes.size() % 4096 == 0) continue;
    IndexEntry entry = *reader->Lookup(key);
    storagetest::FlipByte(file.path, entry.first_page * 4096 + want.bytes.size());
    EXPECT_EQ(reader->ReadBlock(entry), want.bytes);
  }
}

TEST(PageFileCorruption, EveryHeaderByteIsChecked) {
  SmallFile file(20);
  for (std::uint64_t offset = 0; offset < kPageFileHeaderSize; ++offset) {
    storagetest::FlipByte(file.path, offset, 0x10);
    bool version_field = offset >= header_offset::kFormatVersion && offset < header_offset::kFormatVersion + 4;
    std::string message = ExpectError(version_field ? ErrorKind::kNotSupported : ErrorKind::kCorruption,
                                      [&] { PageFileReader::Open(file.path); });
    EXPECT_NE(message.find(file.path), std::string::npos) << message;
    const char* expected_text = offset < 8 ? "wrong magic" : version_field ? "format version" : "header checksum mismatch";
    EXPECT_NE(message.find(expected_text), std::string::npos) << offset << ": " << message;
    storagetest::FlipByte(file.path, offset, 0x10);
  }
  file.ReadEverything();
}

TEST(PageFileCorruption, EveryIndexByteIsChecked) {
  SmallFile file(400);  // 5 leaves and a root at 4 KiB pages
  auto header = PageFileReader::Open(file.path)->header();
  ASSERT_EQ(header.index.height, 2u);
  std::mt19937_64 random(8);
  for (std::uint64_t page = header.index.first_page; page < header.total_page_count; ++page) {
    // The used part of each page: its header and entries.
    std::uint64_t used = kIndexPageHeaderSize +
                         (page == header.index.root_page ? 5 * kInteriorEntrySize : kLeafEntrySize);
    for (std::uint64_t at = 0; at < used; ++at) {
      const std::uint64_t offset = page * 4096 + at;
      const auto mask = static_cast<std::uint8_t>(1u << (random() % 8));
      storagetest::FlipByte(file.path, offset, mask);
      std::string message = ExpectError(ErrorKind::kCorruption, [&] { file.ReadIndex(); });
      EXPECT_NE(message.find("index page " + std::to_string(page)), std::string::npos) << message;
      storagetest::FlipByte(file.path, offset, mask);
    }
  }
  file.ReadEverything();
}

TEST(PageFileCorruption, TruncationAtManyOffsets) {
  SmallFile file(100);
  const Bytes original = storagetest::ReadFileBytes(file.path);
  std::vector<std::uint64_t> sizes = {0, 1, 7, 64, 127, 128, 129, 4095, 4096, 4097};
  for (std::uint64_t size = 8192; size < original.size(); size += 4096 * 7 + 13) sizes.push_back(size);
  sizes.push_back(original.size() - 1);
  for (std::uint64_t size : sizes) {
    storagetest::TruncateFile(file.path, size);
    std::string message = ExpectError(ErrorKind::kCorruption, [&] { PageFileReader::Open(file.path); });
    EXPECT_NE(message.find("truncated"), std::string::npos) << size << ": " << message;
    storagetest::WriteBytesAt(file.path, 0, original);
  }
  // Extra bytes are as wrong as missing ones.
  storagetest::WriteBytesAt(file.path, original.size(), {0});
  std::string message = ExpectError(ErrorKind::kCorruption, [&] { PageFileReader::Open(file.path); });
  EXPECT_NE(message.find("trailing bytes"), std::string::npos) << message;
}

TEST(PageFileCorruption, TruncatedAfterOpenIsCorruptionAtRead) {
  SmallFile file(100);
  auto reader = PageFileReader::Open(file.path);
  storagetest::TruncateFile(file.path, 4096 * 2);
  std::size_t errors = 0;
  for (const auto& [key, want] : file.expected) {
    try {
      if (auto entry = reader->Lookup(key)) {
        EXPECT_EQ(reader->ReadBlock(*entry), want.bytes);
      }
    } catch (const Error& error) {
      EXPECT_EQ(error.kind(), ErrorKind::kCorruption) << error.what();
      EXPECT_NE(std::string(error.what()).find("truncated"), std::string::npos) << error.what();
      ++errors;
    }
  }
  EXPECT_GT(errors, 0u);
}

TEST(PageFileCorruption, UnsupportedVersionAndFlags) {
  SmallFile file(10);
  storagetest::WriteBytesAt(file.path, header_offset::kFormatVersion, {2, 0, 0, 0});
  std::string message = ExpectError(ErrorKind::kNotSupported, [&] { PageFileReader::Open(file.path); });
  EXPECT_NE(message.find("version 2"), std::string::npos) << message;

  // A future flag with a valid checksum: not supported rather than corrupt.
  storagetest::WriteBytesAt(file.path, header_offset::kFormatVersion, {1, 0, 0, 0});
  Bytes header = storagetest::ReadFileBytes(file.path);
  header.resize(kPageFileHeaderSize);
  PutU32(&header[header_offset::kFlags], 4);
  PutU64(&header[header_offset::kChecksum], Checksum64(std::span<const std::uint8_t>(header).first(120)));
  storagetest::WriteBytesAt(file.path, 0, header);
  ExpectError(ErrorKind::kNotSupported, [&] { PageFileReader::Open(file.path); });
}

TEST(PageFileCorruption, NotAPageFile) {
  ScratchDirectory dir;
  const std::string path = dir.File("text.pages");
  std::vector<std::uint8_t> text(8192, 'x');
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(text.data()), 8192);
  std::string message = ExpectError(ErrorKind::kCorruption, [&] { PageFileReader::Open(path); });
  EXPECT_NE(message.find("wrong magic"), std::string::npos) << message;
  ExpectError(ErrorKind::kNotFound, [&] { PageFileReader::Open(dir.File("absent.pages")); });
  // A directory in place of a file: the OS refuses the read.
  std::filesystem::create_directory(dir.File("dir.pages"));
  ExpectError(ErrorKind::kIo, [&] { PageFileReader::Open(dir.File("dir.pages")); });
}

// Edits one index page and re-seals it with a valid checksum, as a buggy
// writer would: the structural checks must still catch what the edit breaks.
// `edit` gets the page's entry count and its entries.
template <typename Edit>
void RewriteIndexPage(const std::string& path, std::uint64_t page_number, std::size_t entry_size, Edit edit) {
  auto header = PageFileReader::Open(path)->header();
  Bytes file_bytes = storagetest::ReadFileBytes(path);
  std::uint8_t* page = &file_bytes[page_number * header.page_size];
  edit(page + 8, page + kIndexPageHeaderSize);
  const std::uint32_t count = GetU32(page + 8);
  std::span<const std::uint8_t> span(page, header.page_size);
  PutU64(page + 24, Checksum64(span.first(24), span.subspan(32, count * entry_size)));
  storagetest::WriteBytesAt(path, page_number * header.page_size, Bytes(page, page + header.page_size));
}

// Rewrites the first leaf entry's location.
void RewriteFirstLeafEntry(const std::string& path, std::uint64_t first_page, std::uint32_t page_count,
                           std::uint64_t byte_length) {
  const std::uint64_t leaf = PageFileReader::Open(path)->header().index.first_page;
  RewriteIndexPage(path, leaf, kLeafEntrySize, [&](std::uint8_t*, std::uint8_t* entry) {
    PutU64(entry + 8, first_page);
    PutU64(entry + 16, byte_length);
    PutU32(entry + 40, page_count);
  });
}

TEST(PageFileCorruption, IndexEntriesOutsideTheDataPages) {
  struct Case {
    const char* what;
    std::uint64_t first_page;
    std::uint32_t page_count;
    std::uint64_t byte_length;
  };
  const std::vector<Case> cases = {
      {"past the end", 1000000, 1, 100},
      {"over the header", 0, 1, 100},
      {"over the index", 0, 0, 0},  // first_page filled in below
      {"straddling the index", 0, 3, 3 * 4096},
      {"pages disagree with length", 1, 1, 5000},
      {"empty but placed", 3, 0, 0},
  };
  for (Case c : cases) {
    SmallFile file(20);
    auto header = PageFileReader::Open(file.path)->header();
    if (std::string(c.what) == "over the index") c = {c.what, header.index.first_page, 1, 10};
    if (std::string(c.what) == "straddling the index") c.first_page = header.index.first_page - 1;
    RewriteFirstLeafEntry(file.path, c.first_page, c.page_count, c.byte_length);
    auto reader = PageFileReader::Open(file.path);
    std::uint64_t first_key = file.expected.begin()->first;
    std::string message = ExpectError(ErrorKind::kCorruption, [&] { reader->Lookup(first_key); });
    EXPECT_NE(message.find("block " + Hex64(first_key) + " (epoch 0): bad index entry"), std::string::npos)
        << c.what << ": " << message;
  }
}

// A root that is consistent in itself but hides part of the leaves from the
// tree: a scan, going leaf by leaf, would find blocks a look-up cannot. Both
// refuse the index instead.
TEST(PageFileCorruption, ARootThatHidesLeavesIsRefused) {
  struct Case {
    const char* what;
    void (*edit)(std::uint8_t* count, std::uint8_t* entries);
  };
  const std::vector<Case> cases = {
      {"one child fewer", [](std::uint8_t* count, std::uint8_t*) { PutU32(count, GetU32(count) - 1); }},
      {"a separator past its child's first key",
       [](std::uint8_t*, std::uint8_t* entries) {
         std::uint8_t* second = entries + kInteriorEntrySize;
         PutU64(second, GetU64(second) + 1);
       }},
      {"a child linked twice",
       [](std::uint8_t*, std::uint8_t* entries) {
         std::uint8_t* second = entries + kInteriorEntrySize;
         PutU64(second + 8, GetU64(entries + 8));
       }},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    SmallFile file(400);  // 5 leaves and a root at 4 KiB pages
    RewriteIndexPage(file.path, PageFileReader::Open(file.path)->header().index.root_page, kInteriorEntrySize,
                     c.edit);
    auto reader = PageFileReader::Open(file.path);
    // The second leaf's first key: the one a look-up misses when the root is wrong.
    std::vector<std::uint64_t> keys;
    for (const auto& [key, want] : file.expected) keys.push_back(key);
    const std::uint64_t hidden = keys[LeafCapacity(file.page_size)];
    std::string message = ExpectError(ErrorKind::kCorruption, [&] { reader->Lookup(hidden); });
    EXPECT_NE(message.find("index page"), std::string::npos) << message;
    ExpectError(ErrorKind::kCorruption,
                [&] { reader->Scan(0, UINT64_MAX, [](const IndexEntry&) { return true; }); });
  }
}

// ---------------------------------------------------------------------------
// A large index: open reads the header only; a look-up reads at most
// `height` index pages.

TEST(PageFileIndex, MillionEntriesLookupReadsAtMostHeightPages) {
  ScratchDirectory dir;
  const std::string path = dir.File("big.pages");
  constexpr std::uint64_t kCount = 1000000;
  // Empty blocks keep the file to its index (~47 MB at 4 KiB pages); keys
  // are spread so that absent keys fall between present ones.
  {
    PageFileWriter writer(path, 4096, kStoreId, 0);
    for (std::uint64_t i = 0; i < kCount; ++i) writer.AddBlock(i * 3 + 1, {}, i);
    writer.Finish();
  }
  auto reader = PageFileReader::Open(path, PageFileReader::Options{16});
  ReaderStats opened = reader->stats();
  EXPECT_EQ(opened.header_reads, 1u);
  EXPECT_EQ(opened.index_page_reads, 0u);
  EXPECT_EQ(opened.bytes_read, kPageFileHeaderSize);
  const std::uint32_t height = reader->index_height();
  EXPECT_EQ(height, 3u);
  EXPECT_EQ(reader->header().index.page_count, ComputeIndexShape(kCount, 4096).total_pages());

  std::mt19937_64 random(12);
  for (int i = 0; i < 2000; ++i) {
    std::uint64_t key = random() % (kCount * 3 + 2);
    std::uint64_t before = reader->stats().index_page_reads;
    std::optional<IndexEntry> entry = reader->Lookup(key);
    std::uint64_t reads = reader->stats().index_page_reads - before;
    EXPECT_LE(reads, height) << Hex64(key);
    if (key % 3 == 1) {
      ASSERT_TRUE(entry.has_value()) << Hex64(key);
      EXPECT_EQ(entry->point_count, key / 3);
    } else {
      EXPECT_FALSE(entry.has_value()) << Hex64(key);
    }
  }
  // The root stays cached: after the first look-up no look-up reads it again.
  reader->DropCaches();
  std::uint64_t before = reader->stats().index_page_reads;
  reader->Lookup(4);
  EXPECT_EQ(reader->stats().index_page_reads - before, height - 1);

  // A full scan visits every entry once, in order.
  std::uint64_t visited = 0;
  bool in_order = true;
  reader->Scan(0, UINT64_MAX, [&](const IndexEntry& entry) {
    in_order = in_order && entry.key == visited * 3 + 1;
    ++visited;
    return true;
  });
  EXPECT_TRUE(in_order);
  EXPECT_EQ(visited, kCount);
}

}  // namespace
}  // namespace octocosm
