// RangeCache: ranges kept between runs within a budget, least recently used
// out first; a damaged entry is never returned. And HttpFile through it: a
// second run reads from the cache, a file changed on the server is fetched
// anew, a damaged entry is fetched again.
#include "storage/range_cache.h"

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include "storage/http_file.h"
#include "tests/support/fake_http_server.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using testing_support::FakeHttpServer;
using testing_support::TempDir;

std::vector<std::uint8_t> Bytes(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<std::uint8_t> bytes(n);
  for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
  return bytes;
}

std::vector<fs::path> EntryFiles(const fs::path& directory) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::recursive_directory_iterator(directory)) {
    if (entry.is_regular_file()) files.push_back(entry.path());
  }
  return files;
}

TEST(RangeCache, KeepsRangesByFileOffsetAndLength) {
  TempDir dir("range-cache");
  auto cache = RangeCache::Open(dir.path().string(), 1 << 20);
  const auto bytes = Bytes(5000, 1);
  cache->Put("file-a", 4096, bytes);
  std::vector<std::uint8_t> out(5000);
  EXPECT_TRUE(cache->Get("file-a", 4096, out));
  EXPECT_EQ(out, bytes);
  EXPECT_FALSE(cache->Get("file-b", 4096, out));  // another file
  EXPECT_FALSE(cache->Get("file-a", 0, out));     // another offset
  std::vector<std::uint8_t> shorter(4999);
  EXPECT_FALSE(cache->Get("file-a", 4096, shorter));  // another length
  EXPECT_EQ(cache->stats().hits, 1u);
  EXPECT_EQ(cache->stats().misses, 3u);

  // Another process (run) finds it, and counts what the directory holds.
  auto again = RangeCache::Open(dir.path().string(), 1 << 20);
  EXPECT_EQ(again->stats().bytes, 5008u);
  std::fill(out.begin(), out.end(), 0);
  EXPECT_TRUE(again->Get("file-a", 4096, out));
  EXPECT_EQ(out, bytes);
}

TEST(RangeCache, ADamagedOrTruncatedEntryIsRemovedNotReturned) {
  TempDir dir("range-cache");
  auto cache = RangeCache::Open(dir.path().string(), 1 << 20);
  const auto bytes = Bytes(3000, 2);
  cache->Put("f", 0, bytes);
  auto files = EntryFiles(dir.path());
  ASSERT_EQ(files.size(), 1u);
  {
    std::fstream file(files[0], std::ios::in | std::ios::out | std::ios::binary);
    file.seekp(1234);
    file.put('\x7f' ^ static_cast<char>(bytes[1234]));
  }
  std::vector<std::uint8_t> out(3000);
  EXPECT_FALSE(cache->Get("f", 0, out));
  EXPECT_EQ(cache->stats().damaged, 1u);
  EXPECT_TRUE(EntryFiles(dir.path()).empty());

  cache->Put("f", 0, bytes);
  files = EntryFiles(dir.path());
  ASSERT_EQ(files.size(), 1u);
  fs::resize_file(files[0], 2000);
  EXPECT_FALSE(cache->Get("f", 0, out));
  EXPECT_EQ(cache->stats().damaged, 2u);
}

TEST(RangeCache, StaysWithinItsBudgetDroppingTheLeastRecentlyUsed) {
  TempDir dir("range-cache");
  auto cache = RangeCache::Open(dir.path().string(), 100000);
  std::vector<std::uint8_t> out(30000);
  for (int i = 0; i < 3; ++i) {
    cache->Put("f", static_cast<std::uint64_t>(i) * 30000, Bytes(30000, static_cast<unsigned>(i)));
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_TRUE(cache->Get("f", 0, out));  // range 0 is now the most recently used
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  cache->Put("f", 90000, Bytes(30000, 3));  // past the budget: evicts down to 90 %
  EXPECT_LE(cache->stats().bytes, 90000u);
  EXPECT_GE(cache->stats().evicted, 1u);
  EXPECT_TRUE(cache->Get("f", 0, out));
  EXPECT_FALSE(cache->Get("f", 30000, out));  // the least recently used
  EXPECT_TRUE(cache->Get("f", 90000, out));
  std::uint64_t total = 0;
  for (const auto& file : EntryFiles(dir.path())) total += fs::file_size(file);
  EXPECT_EQ(total, cache->stats().bytes);
}

TEST(RangeCache, AnHttpFileReadsFromTheCacheInTheNextRun) {
  TempDir dir("range-cache");
  FakeHttpServer server;
  const auto contents = Bytes(1 << 20, 4);
  server.Put("/f", std::string(contents.begin(), contents.end()));
  HttpOptions options;
  options.cache = RangeCache::Open(dir.path().string(), 8 << 20);
  const auto read = [](const HttpFile& file, std::uint64_t offset, std::size_t length) {
    std::vector<std::uint8_t> out(length);
    EXPECT_EQ(file.ReadAt(offset, out), length);
    return out;
  };
  const auto expect = [&](std::uint64_t offset, std::size_t length) {
    return std::vector<std::uint8_t>(contents.begin() + offset, contents.begin() + offset + length);
  };
  {
    auto file = HttpFile::Open(server.Url("/f"), options);
    EXPECT_EQ(read(*file, 300000, 70000), expect(300000, 70000));
    EXPECT_EQ(file->stats().requests, 2u);
  }
  {
    auto file = HttpFile::Open(server.Url("/f"), options);  // the next run: only the open asks the server
    EXPECT_EQ(read(*file, 300000, 70000), expect(300000, 70000));
    EXPECT_EQ(file->stats().requests, 1u);
  }
  // A damaged entry is fetched again.
  for (const auto& path : EntryFiles(dir.path())) {
    std::fstream file(path, std::ios::in | std::ios::out | std::ios::binary);
    file.seekp(10);
    file.put('\x01');
    file.seekp(11);
    file.put('\x02');
  }
  {
    auto file = HttpFile::Open(server.Url("/f"), options);
    EXPECT_EQ(read(*file, 300000, 70000), expect(300000, 70000));
    EXPECT_EQ(file->stats().requests, 2u);
  }
  // The file changed on the server: its new version is fetched, not the copy.
  auto changed = contents;
  changed[300001] ^= 0xff;
  changed.push_back(7);  // the fake server's ETag follows the size
  server.Put("/f", std::string(changed.begin(), changed.end()));
  {
    auto file = HttpFile::Open(server.Url("/f"), options);
    std::vector<std::uint8_t> out = read(*file, 300000, 70000);
    EXPECT_EQ(out[1], changed[300001]);
    EXPECT_EQ(file->stats().requests, 2u);
  }
}

}  // namespace
}  // namespace octocosm
