// The ID census and the dense (ID -> leaf) table (ingest/dense_id_table.h):
// the census accepts exactly the ID sets that are unique and span at most its
// limit, whatever order the IDs arrive in, and reports their range; the table
// gives back every recorded pair in ID order and refuses IDs it cannot hold.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <optional>
#include <random>
#include <set>
#include <thread>
#include <utility>
#include <vector>

#include "base/error.h"
#include "ingest/dense_id_table.h"

namespace octocosm {
namespace {

// Feeds `ids` to a census in batches of `batch`.
IdCensus Census(const std::vector<std::uint64_t>& ids, std::uint64_t max_span, std::size_t batch = 1000) {
  IdCensus census(max_span);
  for (std::size_t i = 0; i < ids.size(); i += batch) {
    census.Add(std::span<const std::uint64_t>(ids).subspan(i, std::min(batch, ids.size() - i)));
  }
  return census;
}

TEST(IdCensus, ShuffledConsecutiveIdsAreDense) {
  std::vector<std::uint64_t> ids(100000);
  std::iota(ids.begin(), ids.end(), 1);
  std::shuffle(ids.begin(), ids.end(), std::mt19937_64(3));
  const IdCensus census = Census(ids, ids.size());
  EXPECT_TRUE(census.dense());
  EXPECT_EQ(census.first(), 1u);
  EXPECT_EQ(census.span(), ids.size());
  EXPECT_EQ(census.count(), ids.size());
}

TEST(IdCensus, DecreasingIdsFarFromZeroAreDense) {
  // The bitmap grows downwards, towards ID 0, geometrically.
  const std::uint64_t top = (std::uint64_t{1} << 50) + 12345;
  std::vector<std::uint64_t> ids;
  for (std::uint64_t i = 0; i < 200000; ++i) ids.push_back(top - 2 * i);
  const IdCensus census = Census(ids, 400000, 1);
  EXPECT_TRUE(census.dense());
  EXPECT_EQ(census.first(), top - 2 * 199999);
  EXPECT_EQ(census.span(), 2 * 199999 + 1u);
}

TEST(IdCensus, IdsNearZeroAndNearTheTopOfTheRange) {
  EXPECT_TRUE(Census({3, 0, 2, 1}, 4).dense());
  const std::uint64_t max = ~std::uint64_t{0};
  const IdCensus top = Census({max, max - 1, max - 70, max - 200}, 201);
  EXPECT_TRUE(top.dense());
  EXPECT_EQ(top.first(), max - 200);
  EXPECT_EQ(top.span(), 201u);
}

TEST(IdCensus, ADuplicateGivesUp) {
  const IdCensus census = Census({5, 9, 7, 9, 6}, 100);
  EXPECT_FALSE(census.dense());
}

TEST(IdCensus, TheSpanLimitIsInclusive) {
  EXPECT_TRUE(Census({100, 1099}, 1000).dense());
  EXPECT_FALSE(Census({100, 1100}, 1000).dense());
  EXPECT_FALSE(Census({1100, 100}, 1000).dense());
  EXPECT_FALSE(Census({0, ~std::uint64_t{0}}, ~std::uint64_t{0}).dense());  // 2^64 values
}

TEST(IdCensus, RoomMadeBelowDoesNotRefuseIdsAbove) {
  // After 1000..1639, ID 950 makes room below (the bitmap grows ahead, by
  // as much as it holds, within the limit); IDs up to 950 + 999 must still
  // fit a span of 1000, which needs that room back.
  std::vector<std::uint64_t> ids;
  for (std::uint64_t id = 1000; id <= 1639; ++id) ids.push_back(id);
  ids.push_back(950);
  for (std::uint64_t id = 1640; id <= 1949; ++id) ids.push_back(id);
  const IdCensus census = Census(ids, 1000, 1);
  EXPECT_TRUE(census.dense());
  EXPECT_EQ(census.first(), 950u);
  EXPECT_EQ(census.span(), 1000u);
}

TEST(IdCensus, AgreesWithASetOnRandomIds) {
  std::mt19937_64 rng(17);
  for (int trial = 0; trial < 300; ++trial) {
    const std::uint64_t base = std::uniform_int_distribution<std::uint64_t>(0, 1u << 20)(rng) * (trial % 3 == 0 ? 1u << 30 : 1u);
    const std::uint64_t range = std::uniform_int_distribution<std::uint64_t>(1, 5000)(rng);
    const std::size_t count = std::uniform_int_distribution<std::size_t>(1, 3000)(rng);
    std::vector<std::uint64_t> ids(count);
    for (auto& id : ids) id = base + std::uniform_int_distribution<std::uint64_t>(0, range - 1)(rng);
    const std::uint64_t max_span = std::uniform_int_distribution<std::uint64_t>(1, 6000)(rng);
    const std::set<std::uint64_t> unique(ids.begin(), ids.end());
    const std::uint64_t span = *unique.rbegin() - *unique.begin() + 1;
    const IdCensus census = Census(ids, max_span, 1 + trial % 7);
    ASSERT_EQ(census.dense(), unique.size() == ids.size() && span <= max_span) << "trial " << trial;
    if (census.dense()) {
      EXPECT_EQ(census.first(), *unique.begin());
      EXPECT_EQ(census.span(), span);
      EXPECT_EQ(census.count(), ids.size());
    }
  }
}

TEST(DenseIdTable, GivesEveryIdItsLeaf) {
  const std::uint64_t first = 1000;
  DenseIdTable table(first, 3000);
  // Two leaves recorded from two threads at once; every third ID is absent.
  std::vector<std::uint64_t> a, b;
  for (std::uint64_t id = first; id < first + 3000; id += 3) (id % 2 == 0 ? a : b).push_back(id);
  const NodeKey leaf_a = NodeKey::Root().Child(1).Child(5), leaf_b = NodeKey::Root().Child(6);
  std::thread other([&] { EXPECT_FALSE(table.Add(b, leaf_b)); });
  EXPECT_FALSE(table.Add(a, leaf_a));
  other.join();
  ASSERT_TRUE(table.narrow());
  ASSERT_EQ(table.narrow_slots().size(), 3000u);
  EXPECT_TRUE(table.wide_slots().empty());
  ASSERT_EQ(table.leaves().size(), 2u);
  for (std::uint64_t i = 0; i < 3000; ++i) {
    const std::uint64_t id = first + i;
    const std::uint32_t slot = table.narrow_slots()[i];
    if (i % 3 != 0) {
      ASSERT_EQ(slot, 0u) << id;
      continue;
    }
    ASSERT_GE(slot, 1u) << id;
    ASSERT_LE(slot, 2u) << id;
    ASSERT_EQ(table.leaves()[slot - 1], (id % 2 == 0 ? leaf_a : leaf_b).value()) << id;
  }
}

// Past 65535 leaves the slots turn 32 bits wide, keeping what the narrow
// ones held, while other threads keep adding leaves.
TEST(DenseIdTable, WidensItsSlotsPastTheMostNarrowLeaves) {
  const std::uint64_t first = 7;
  const std::uint64_t leaves = DenseIdTable::kMostNarrowLeaves + 40;
  const std::uint64_t span = 2 * leaves + 5;  // two IDs a leaf, and a few absent at the end
  DenseIdTable table(first, span);
  // Leaf j holds IDs first + 2j and first + 2j + 1; even leaves from one
  // thread, odd from another, so both are adding when the table widens.
  const auto add_leaves = [&](std::uint64_t parity) {
    for (std::uint64_t j = parity; j < leaves; j += 2) {
      const std::vector<std::uint64_t> ids = {first + 2 * j, first + 2 * j + 1};
      EXPECT_FALSE(table.Add(ids, NodeKey::FromValue(NodeKey::Root().DescendantRange(8).first + j)));
    }
  };
  std::thread other(add_leaves, 1);
  add_leaves(0);
  other.join();
  ASSERT_FALSE(table.narrow());
  EXPECT_TRUE(table.narrow_slots().empty());
  ASSERT_EQ(table.wide_slots().size(), span);
  ASSERT_EQ(table.leaves().size(), leaves);
  for (std::uint64_t i = 0; i < span; ++i) {
    const std::uint32_t slot = table.wide_slots()[i];
    if (i >= 2 * leaves) {
      ASSERT_EQ(slot, 0u) << i;
      continue;
    }
    ASSERT_GE(slot, 1u) << i;
    ASSERT_LE(slot, leaves) << i;
    ASSERT_EQ(table.leaves()[slot - 1], NodeKey::Root().DescendantRange(8).first + i / 2) << i;
  }
}

// Exactly 65535 leaves still fit 16-bit slots.
TEST(DenseIdTable, StaysNarrowUpToTheMostNarrowLeaves) {
  const std::uint64_t leaves = DenseIdTable::kMostNarrowLeaves;
  DenseIdTable table(0, leaves);
  for (std::uint64_t j = 0; j < leaves; ++j) {
    const std::vector<std::uint64_t> ids = {j};
    EXPECT_FALSE(table.Add(ids, NodeKey::Root()));
  }
  ASSERT_TRUE(table.narrow());
  for (std::uint64_t i = 0; i < leaves; ++i) ASSERT_EQ(table.narrow_slots()[i], i + 1) << i;
}

// Leaves come in the order threads finish them; sorted, the table is the
// same whatever that order was, narrow or wide.
TEST(DenseIdTable, SortedLeavesMakeTheSameTableInAnyOrderOfAdding) {
  for (const std::uint64_t leaves : {std::uint64_t{300}, DenseIdTable::kMostNarrowLeaves + 3}) {
    std::vector<std::uint64_t> order(leaves);
    std::iota(order.begin(), order.end(), 0);
    std::vector<std::pair<std::vector<std::uint64_t>, std::vector<std::uint32_t>>> tables;
    for (const std::uint64_t seed : {1, 2}) {
      std::shuffle(order.begin(), order.end(), std::mt19937_64(seed));
      DenseIdTable table(10, 3 * leaves + 4);  // three IDs a leaf, the last of each absent
      for (const std::uint64_t j : order) {
        const std::vector<std::uint64_t> ids = {10 + 3 * j, 11 + 3 * j};
        EXPECT_FALSE(table.Add(ids, NodeKey::FromValue(NodeKey::Root().DescendantRange(8).first + (j * 7919) % leaves)));
      }
      table.SortLeaves(2);
      ASSERT_TRUE(std::is_sorted(table.leaves().begin(), table.leaves().end()));
      std::vector<std::uint32_t> slots;
      if (table.narrow()) {
        slots.assign(table.narrow_slots().begin(), table.narrow_slots().end());
      } else {
        slots.assign(table.wide_slots().begin(), table.wide_slots().end());
      }
      for (std::uint64_t i = 0; i < slots.size(); ++i) {
        if (i % 3 == 2 || i >= 3 * leaves) {
          ASSERT_EQ(slots[i], 0u) << i;
          continue;
        }
        ASSERT_EQ(table.leaves()[slots[i] - 1], NodeKey::Root().DescendantRange(8).first + (i / 3 * 7919) % leaves) << i;
      }
      tables.emplace_back(std::vector<std::uint64_t>(table.leaves().begin(), table.leaves().end()), slots);
    }
    EXPECT_EQ(tables[0], tables[1]) << leaves << " leaves";
  }
}

TEST(DenseIdTable, RefusesIdsOutsideItsRange) {
  DenseIdTable table(50, 10);
  const NodeKey leaf = NodeKey::Root().Child(2);
  const std::vector<std::uint64_t> below = {49}, above = {60};
  EXPECT_THROW((void)table.Add(below, leaf), Error);
  EXPECT_THROW((void)table.Add(above, leaf), Error);
}

// A repeated ID, within one leaf or in a later one, is returned (the first
// in the leaf's list), and its slot keeps the leaf that recorded it first.
TEST(DenseIdTable, ReturnsTheFirstIdRecordedBefore) {
  DenseIdTable table(50, 10);
  const NodeKey a = NodeKey::Root().Child(2), b = NodeKey::Root().Child(5);
  const std::vector<std::uint64_t> first = {50, 51, 52}, within = {53, 54, 53}, later = {56, 57, 52, 51};
  EXPECT_EQ(table.Add(first, a), std::nullopt);
  EXPECT_EQ(table.Add(within, a), std::optional<std::uint64_t>(53));
  EXPECT_EQ(table.Add(later, b), std::optional<std::uint64_t>(52));
  ASSERT_TRUE(table.narrow());
  EXPECT_EQ(table.narrow_slots()[2], 1u) << "ID 52 keeps the first leaf";
  EXPECT_EQ(table.narrow_slots()[1], 1u);
  EXPECT_EQ(table.narrow_slots()[6], 3u) << "the later leaf's other IDs are recorded";
}

}  // namespace
}  // namespace octocosm
