// The radix sort against std::stable_sort: same order, equal keys included.
#include "index/radix_sort.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

namespace octocosm {
namespace {

struct Record {
  std::uint64_t key;
  std::uint32_t input_index;
};

std::vector<Record> Sorted(std::vector<Record> records) {
  std::vector<Record> scratch(records.size());
  const std::span<Record> sorted =
      RadixSortByKey(std::span<Record>(records), std::span<Record>(scratch), [](const Record& r) { return r.key; });
  EXPECT_TRUE(sorted.data() == records.data() || sorted.data() == scratch.data());
  return {sorted.begin(), sorted.end()};
}

TEST(RadixSort, MatchesAStableSortForKeysOfAnyWidth) {
  std::mt19937_64 random(7);
  // Keys differing in no byte, in one, in three low ones (IDs below 2^24),
  // in a high one only, and in all eight; many repeats in the narrow cases.
  for (const std::uint64_t mask : {0x0ull, 0xFFull, 0xFFFFFFull, 0xFF00000000000000ull, ~0ull}) {
    for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{2}, std::size_t{1000}, std::size_t{50000}}) {
      SCOPED_TRACE("mask " + std::to_string(mask) + ", n " + std::to_string(n));
      std::vector<Record> records(n);
      for (std::size_t i = 0; i < n; ++i) records[i] = {(random() & mask) | 0x1234, static_cast<std::uint32_t>(i)};
      std::vector<Record> expected = records;
      std::stable_sort(expected.begin(), expected.end(), [](const Record& a, const Record& b) { return a.key < b.key; });
      const std::vector<Record> actual = Sorted(records);
      ASSERT_EQ(actual.size(), expected.size());
      for (std::size_t i = 0; i < n; ++i) {
        ASSERT_EQ(actual[i].key, expected[i].key) << i;
        ASSERT_EQ(actual[i].input_index, expected[i].input_index) << "equal keys keep their input order, at " << i;
      }
    }
  }
}

TEST(RadixSort, SortsASubrangeInPlaceOfAnyOffset) {
  std::vector<Record> records = {{9, 0}, {5, 1}, {7, 2}, {5, 3}, {1, 4}};
  std::vector<Record> scratch(3);
  const std::span<Record> middle(records.data() + 1, 3);
  const std::span<Record> sorted =
      RadixSortByKey(middle, std::span<Record>(scratch), [](const Record& r) { return r.key; });
  ASSERT_EQ(sorted.size(), 3u);
  EXPECT_EQ(sorted[0].input_index, 1u);
  EXPECT_EQ(sorted[1].input_index, 3u);
  EXPECT_EQ(sorted[2].input_index, 2u);
  EXPECT_EQ(records[0].input_index, 0u) << "outside the range nothing moves";
  EXPECT_EQ(records[4].input_index, 4u);
}

}  // namespace
}  // namespace octocosm
