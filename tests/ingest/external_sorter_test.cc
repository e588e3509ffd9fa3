// The external sorter (ingest/external_sorter.h): records come back
// sorted by key, every one of them, equal keys in the order they were added
// (per thread when several threads add at once), and its run files are gone
// when it is.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <random>
#include <thread>
#include <vector>

#include "base/error.h"
#include "ingest/external_sorter.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

struct Record {
  std::uint64_t key;
  std::uint64_t origin;  // adder << 32 | its sequence number
};

std::vector<Record> ReadAll(const ExternalSorter<Record>& sorter) {
  std::vector<Record> out;
  auto reader = sorter.Open();
  Record r{};
  while (reader.Next(r)) out.push_back(r);
  return out;
}

std::size_t FilesIn(const fs::path& directory) {
  return static_cast<std::size_t>(std::distance(fs::directory_iterator(directory), fs::directory_iterator()));
}

// Sorted by key; equal keys from one adder in the order it added them; and
// exactly the records added (`added[t]` holds adder t's, in order).
void ExpectSortedAndComplete(const std::vector<Record>& out, const std::vector<std::vector<Record>>& added) {
  std::size_t total = 0;
  for (const auto& records : added) total += records.size();
  ASSERT_EQ(out.size(), total);
  for (std::size_t i = 1; i < out.size(); ++i) {
    ASSERT_LE(out[i - 1].key, out[i].key) << "at " << i;
    if (out[i - 1].key == out[i].key && (out[i - 1].origin >> 32) == (out[i].origin >> 32)) {
      ASSERT_LT(out[i - 1].origin, out[i].origin) << "equal keys of one adder out of order at " << i;
    }
  }
  std::vector<bool> seen(total, false);
  std::vector<std::size_t> first_of(added.size() + 1, 0);
  for (std::size_t t = 0; t < added.size(); ++t) first_of[t + 1] = first_of[t] + added[t].size();
  for (const Record& r : out) {
    const std::size_t adder = r.origin >> 32;
    const std::size_t sequence = r.origin & 0xffffffffu;
    ASSERT_LT(adder, added.size());
    ASSERT_LT(sequence, added[adder].size());
    ASSERT_EQ(added[adder][sequence].key, r.key);
    ASSERT_FALSE(seen[first_of[adder] + sequence]) << "record returned twice";
    seen[first_of[adder] + sequence] = true;
  }
}

std::vector<Record> RandomRecords(std::size_t adder, std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<std::uint64_t> key(0, n / 4);  // plenty of equal keys
  std::vector<Record> records(n);
  for (std::size_t i = 0; i < n; ++i) records[i] = {key(rng) << 20, (std::uint64_t{adder} << 32) | i};
  return records;
}

TEST(ExternalSorter, OneRunStaysInMemoryAndSortsStably) {
  testing_support::TempDir dir("sorter-one-run");
  ExternalSorter<Record> sorter((dir.path() / "s").string(), 100000);
  const std::vector<Record> records = RandomRecords(0, 5000, 1);
  sorter.Add(records);
  sorter.Finish();
  EXPECT_EQ(sorter.run_count(), 1u);
  EXPECT_EQ(FilesIn(dir.path()), 0u);
  ExpectSortedAndComplete(ReadAll(sorter), {records});
}

TEST(ExternalSorter, RunsOnDiskMergeStablyAndAreRemoved) {
  testing_support::TempDir dir("sorter-runs");
  const std::vector<Record> records = RandomRecords(0, 20000, 2);
  {
    ExternalSorter<Record> sorter((dir.path() / "s").string(), 999);
    sorter.Reserve(records.size());
    for (std::size_t i = 0; i < records.size(); i += 357) {
      sorter.Add(std::span<const Record>(records).subspan(i, std::min<std::size_t>(357, records.size() - i)));
    }
    sorter.Finish();
    EXPECT_EQ(sorter.run_count(), (records.size() + 998) / 999);
    EXPECT_EQ(FilesIn(dir.path()), sorter.run_count());
    ExpectSortedAndComplete(ReadAll(sorter), {records});
  }
  EXPECT_EQ(FilesIn(dir.path()), 0u);
}

// Runs whose key ranges follow one another, touching at their ends (equal
// keys across runs come back in run order) and overlapping in places: the
// merge keeps taking from one run while it stays ahead.
TEST(ExternalSorter, RunsWithAdjacentRangesMergeStably) {
  testing_support::TempDir dir("sorter-adjacent");
  std::vector<Record> records;
  for (std::uint64_t i = 0; i < 10000; ++i) {
    const std::uint64_t run = i / 1000;
    // Mostly ascending; each run's last keys equal the next run's first and
    // every fifth run reaches back into the one before.
    std::uint64_t key = run * 99 + (i % 1000) / 10;
    if (run % 5 == 4 && i % 1000 < 200) key -= 150;
    records.push_back({key, i});
  }
  ExternalSorter<Record> sorter((dir.path() / "s").string(), 1000);
  sorter.Add(records);
  sorter.Finish();
  EXPECT_EQ(sorter.run_count(), 10u);
  ExpectSortedAndComplete(ReadAll(sorter), {records});  // one adder: equal keys in the order added
}

TEST(ExternalSorter, ConcurrentAddersLoseNothing) {
  testing_support::TempDir dir("sorter-threads");
  constexpr std::size_t kAdders = 4;
  std::vector<std::vector<Record>> added(kAdders);
  for (std::size_t t = 0; t < kAdders; ++t) added[t] = RandomRecords(t, 30000 + 1000 * t, 10 + t);
  {
    ExternalSorter<Record> sorter((dir.path() / "s").string(), 2500);
    sorter.Reserve(200000);
    std::vector<std::thread> threads;
    for (std::size_t t = 0; t < kAdders; ++t) {
      threads.emplace_back([&, t] {
        std::mt19937_64 rng(100 + t);
        std::uniform_int_distribution<std::size_t> batch(1, 700);
        std::span<const Record> left(added[t]);
        while (!left.empty()) {
          const std::size_t take = std::min(batch(rng), left.size());
          sorter.Add(left.first(take));
          left = left.subspan(take);
        }
      });
    }
    for (std::thread& thread : threads) thread.join();
    sorter.Finish();
    EXPECT_GT(sorter.run_count(), 40u);
    ExpectSortedAndComplete(ReadAll(sorter), added);
  }
  EXPECT_EQ(FilesIn(dir.path()), 0u);
}

TEST(ExternalSorter, AddAfterFinishIsRefused) {
  testing_support::TempDir dir("sorter-finished");
  ExternalSorter<Record> sorter((dir.path() / "s").string(), 10);
  sorter.Add(Record{1, 0});
  sorter.Finish();
  EXPECT_THROW(sorter.Add(Record{2, 1}), Error);
}

}  // namespace
}  // namespace octocosm
