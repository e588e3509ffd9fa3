// How an epoch is cut among ranks (ingest/epoch_domains.h): every point in
// exactly one domain, domains in depth-first order with nondecreasing
// owners, no domain below a node that the tree makes a leaf, and shares of
// about equal points.
#include "ingest/epoch_domains.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "base/error.h"

namespace octocosm {
namespace {

constexpr int kLevel = 3;
constexpr std::size_t kCells = std::size_t{1} << (3 * kLevel);

std::uint64_t PointsBelow(NodeKey node, const std::vector<std::uint64_t>& cells) {
  const auto [first, last] = node.DescendantRange(kLevel);
  std::uint64_t sum = 0;
  for (std::uint64_t v = first; v <= last; ++v) sum += cells[v - kCells];
  return sum;
}

// Clumps of points in a sparse background, as clustered snapshots have.
std::vector<std::uint64_t> ClumpedCells(unsigned seed) {
  std::mt19937_64 random(seed);
  std::vector<std::uint64_t> cells(kCells, 0);
  for (std::size_t c = 0; c < kCells; ++c) cells[c] = random() % 4 == 0 ? random() % 50 : 0;
  for (int clump = 0; clump < 6; ++clump) cells[random() % kCells] += 20000 + random() % 100000;
  return cells;
}

void CheckDomains(const EpochDomains& domains, const std::vector<std::uint64_t>& cells, std::uint64_t capacity,
                  int ranks) {
  ASSERT_EQ(domains.keys.size(), domains.owner.size());
  std::vector<int> covered(kCells, 0);
  std::vector<std::uint64_t> share(static_cast<std::size_t>(ranks), 0);
  for (std::size_t d = 0; d < domains.keys.size(); ++d) {
    const NodeKey key = domains.keys[d];
    ASSERT_LE(key.level(), kLevel);
    EXPECT_GT(PointsBelow(key, cells), 0u) << key.Path();
    if (d > 0) {
      EXPECT_TRUE(PreorderLess{}(domains.keys[d - 1], key)) << key.Path();
      EXPECT_FALSE(domains.keys[d - 1].IsAncestorOrSelf(key)) << key.Path();
      EXPECT_LE(domains.owner[d - 1], domains.owner[d]);
    }
    ASSERT_GE(domains.owner[d], 0);
    ASSERT_LT(domains.owner[d], ranks);
    // A node above the domain holds more than a leaf: the domain's subtree
    // is what a single build makes of it.
    for (int level = 0; level < key.level(); ++level) {
      EXPECT_GT(PointsBelow(key.AncestorAt(level), cells), capacity) << key.Path();
    }
    const auto [first, last] = key.DescendantRange(kLevel);
    for (std::uint64_t v = first; v <= last; ++v) {
      ++covered[v - kCells];
      if (cells[v - kCells] > 0) EXPECT_EQ(domains.cell_domain[v - kCells], d);
    }
    share[static_cast<std::size_t>(domains.owner[d])] += PointsBelow(key, cells);
  }
  std::uint64_t total = 0, largest_cell = 0;
  for (std::size_t c = 0; c < kCells; ++c) {
    if (cells[c] > 0) EXPECT_EQ(covered[c], 1) << "cell " << c;
    total += cells[c];
    largest_cell = std::max(largest_cell, cells[c]);
  }
  // A share is off its even part by at most the largest unit it could not cut.
  for (int r = 0; r < ranks; ++r) {
    const double even = static_cast<double>(total) / ranks;
    EXPECT_LE(std::fabs(static_cast<double>(share[static_cast<std::size_t>(r)]) - even),
              static_cast<double>(largest_cell) + 1)
        << "rank " << r;
  }
}

TEST(EpochDomains, EveryPointIsInOneDomainAndSharesAreEven) {
  for (unsigned seed = 1; seed <= 20; ++seed) {
    const std::vector<std::uint64_t> cells = ClumpedCells(seed);
    for (int ranks : {1, 2, 3, 4, 7, 16}) {
      for (std::uint64_t capacity : {std::uint64_t{100}, std::uint64_t{5000}}) {
        SCOPED_TRACE("seed " + std::to_string(seed) + ", " + std::to_string(ranks) + " ranks, capacity " +
                     std::to_string(capacity));
        CheckDomains(ShareDomains(cells, kLevel, capacity, ranks), cells, capacity, ranks);
      }
    }
  }
}

TEST(EpochDomains, OneRankHoldsTheRootAndASmallEpochIsOneLeaf) {
  const std::vector<std::uint64_t> cells = ClumpedCells(3);
  EpochDomains one = ShareDomains(cells, kLevel, 100, 1);
  ASSERT_EQ(one.keys.size(), 1u);
  EXPECT_EQ(one.keys[0], NodeKey::Root());
  std::vector<std::uint64_t> few(kCells, 0);
  few[5] = 30;
  few[400] = 40;
  EpochDomains small = ShareDomains(few, kLevel, 100, 4);
  ASSERT_EQ(small.keys.size(), 1u);
  EXPECT_EQ(small.keys[0], NodeKey::Root());
}

TEST(EpochDomains, MoreRanksThanUnitsLeaveSomeWithout) {
  std::vector<std::uint64_t> cells(kCells, 0);
  cells[0] = 1000;
  cells[kCells - 1] = 1000;
  const EpochDomains domains = ShareDomains(cells, kLevel, 100, 8);
  CheckDomains(domains, cells, 100, 8);
  EXPECT_EQ(domains.keys.size(), 2u);
}

TEST(EpochDomains, RefusesCountsOfTheWrongSize) {
  const std::vector<std::uint64_t> cells(100, 1);
  EXPECT_THROW(ShareDomains(cells, kLevel, 100, 2), Error);
  EXPECT_THROW(ShareDomains(std::vector<std::uint64_t>(kCells, 1), kLevel, 100, 0), Error);
}

}  // namespace
}  // namespace octocosm
