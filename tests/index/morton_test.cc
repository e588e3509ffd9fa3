// Node keys checked exhaustively at small depths, at random at depth 21, and
// against a naive bit-by-bit reference.
#include "index/morton.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>

#include "base/error.h"

namespace octocosm {
namespace {

// The reference: interleave one bit at a time.
std::uint64_t NaiveKey(int level, CellCoord c) {
  std::uint64_t m = 0;
  for (int i = 0; i < level; ++i) {
    m |= static_cast<std::uint64_t>((c.x >> i) & 1) << (3 * i);
    m |= static_cast<std::uint64_t>((c.y >> i) & 1) << (3 * i + 1);
    m |= static_cast<std::uint64_t>((c.z >> i) & 1) << (3 * i + 2);
  }
  return m | (std::uint64_t{1} << (3 * level));
}

TEST(NodeKey, ExhaustiveRoundTripAtSmallDepths) {
  for (int level = 0; level <= 4; ++level) {
    const std::uint32_t n = 1u << level;
    std::set<std::uint64_t> seen;
    for (std::uint32_t x = 0; x < n; ++x)
      for (std::uint32_t y = 0; y < n; ++y)
        for (std::uint32_t z = 0; z < n; ++z) {
          const CellCoord c{x, y, z};
          const NodeKey key = NodeKey::FromCell(level, c);
          ASSERT_EQ(key.value(), NaiveKey(level, c));
          ASSERT_TRUE(key.IsValid());
          ASSERT_EQ(key.level(), level);
          ASSERT_EQ(key.cell(), c);
          ASSERT_EQ(NodeKey::FromPath(key.Path()), key);
          if (level > 0) {
            const NodeKey parent = key.Parent();
            ASSERT_EQ(parent, NodeKey::FromCell(level - 1, {x / 2, y / 2, z / 2}));
            ASSERT_EQ(key.OctantInParent(), static_cast<int>((x & 1) | ((y & 1) << 1) | ((z & 1) << 2)));
            ASSERT_EQ(parent.Child(key.OctantInParent()), key);
            ASSERT_TRUE(parent.IsAncestorOrSelf(key));
            ASSERT_FALSE(key.IsAncestorOrSelf(parent));
          }
          seen.insert(key.value());
        }
    // All keys of a level are distinct and fill [2^3L, 2^(3L+1)) exactly.
    ASSERT_EQ(seen.size(), std::size_t{n} * n * n);
    EXPECT_EQ(*seen.begin(), std::uint64_t{1} << (3 * level));
    EXPECT_EQ(*seen.rbegin(), (std::uint64_t{1} << (3 * level + 1)) - 1);
  }
}

TEST(NodeKey, RandomRoundTripAtDepth21) {
  std::mt19937_64 rng(21);
  std::uniform_int_distribution<std::uint32_t> coord(0, (1u << kMaxLevel) - 1);
  for (int i = 0; i < 200000; ++i) {
    const CellCoord c{coord(rng), coord(rng), coord(rng)};
    const NodeKey key = NodeKey::FromCell(kMaxLevel, c);
    ASSERT_EQ(key.value(), NaiveKey(kMaxLevel, c));
    ASSERT_TRUE(key.IsValid());
    ASSERT_EQ(key.level(), kMaxLevel);
    ASSERT_EQ(key.cell(), c);
    // Walking up to the root and back down by octants reproduces the key.
    NodeKey up = key;
    std::vector<int> octants;
    while (up.level() > 0) {
      octants.push_back(up.OctantInParent());
      up = up.Parent();
    }
    ASSERT_EQ(up, NodeKey::Root());
    NodeKey down = NodeKey::Root();
    for (auto it = octants.rbegin(); it != octants.rend(); ++it) down = down.Child(*it);
    ASSERT_EQ(down, key);
    const int a = static_cast<int>(i % (kMaxLevel + 1));
    ASSERT_EQ(key.AncestorAt(a), NodeKey::FromCell(a, {c.x >> (kMaxLevel - a), c.y >> (kMaxLevel - a), c.z >> (kMaxLevel - a)}));
  }
  // The deepest, largest key uses bit 63 as its sentinel.
  const std::uint32_t m = (1u << kMaxLevel) - 1;
  EXPECT_EQ(NodeKey::FromCell(kMaxLevel, {m, m, m}).value(), ~std::uint64_t{0});
}

TEST(NodeKey, InvalidKeysAndPaths) {
  EXPECT_FALSE(NodeKey().IsValid());
  EXPECT_FALSE(NodeKey::FromValue(2).IsValid());   // sentinel at bit 1
  EXPECT_FALSE(NodeKey::FromValue(0x20).IsValid());  // sentinel at bit 5
  EXPECT_TRUE(NodeKey::FromValue(8).IsValid());
  EXPECT_THROW(NodeKey::FromPath(""), Error);
  EXPECT_THROW(NodeKey::FromPath("x01"), Error);
  EXPECT_THROW(NodeKey::FromPath("r018"), Error);
  EXPECT_THROW(NodeKey::FromPath("r" + std::string(22, '0')), Error);
  EXPECT_EQ(NodeKey::FromPath("r").value(), 1u);
  EXPECT_EQ(NodeKey::Root().Child(7).Child(2).Path(), "r72");
}

TEST(NodeKey, DescendantRangeHoldsExactlyTheDescendants) {
  for (int level = 0; level <= 2; ++level) {
    const std::uint32_t n = 1u << level;
    for (std::uint32_t i = 0; i < n * n * n; ++i) {
      const NodeKey node = NodeKey::FromValue((std::uint64_t{1} << (3 * level)) | i);
      for (int dl = level; dl <= 4; ++dl) {
        const KeyRange r = node.DescendantRange(dl);
        const std::uint32_t m = 1u << dl;
        std::uint64_t count = 0;
        for (std::uint64_t v = std::uint64_t{1} << (3 * dl); v < (std::uint64_t{1} << (3 * dl)) + m * m * m; ++v) {
          const bool in_range = v >= r.first && v <= r.last;
          ASSERT_EQ(in_range, node.IsAncestorOrSelf(NodeKey::FromValue(v)));
          count += in_range;
        }
        ASSERT_EQ(count, std::uint64_t{1} << (3 * (dl - level)));
      }
    }
  }
}

TEST(NodeKey, PreorderMatchesPathOrder) {
  // Depth-first order is the lexicographic order of paths ("r", "r0", "r00", ..., "r01", ...).
  std::vector<NodeKey> keys;
  for (int level = 0; level <= 3; ++level)
    for (std::uint64_t i = 0; i < (std::uint64_t{1} << (3 * level)); ++i)
      keys.push_back(NodeKey::FromValue((std::uint64_t{1} << (3 * level)) | i));
  std::mt19937_64 rng(3);
  std::shuffle(keys.begin(), keys.end(), rng);
  std::vector<NodeKey> by_preorder = keys, by_path = keys;
  std::sort(by_preorder.begin(), by_preorder.end(), PreorderLess{});
  std::sort(by_path.begin(), by_path.end(), [](NodeKey a, NodeKey b) { return a.Path() < b.Path(); });
  EXPECT_EQ(by_preorder, by_path);
  // Numeric order is level-major.
  std::sort(keys.begin(), keys.end());
  for (std::size_t i = 1; i < keys.size(); ++i) ASSERT_LE(keys[i - 1].level(), keys[i].level());
}

// Brute force: the sorted keys of every cell in the box.
std::vector<std::uint64_t> NaiveCover(int level, CellBox box) {
  std::vector<std::uint64_t> keys;
  const std::uint32_t n = 1u << level;
  for (std::uint32_t x = box.lo.x; x <= std::min(box.hi.x, n - 1); ++x)
    for (std::uint32_t y = box.lo.y; y <= std::min(box.hi.y, n - 1); ++y)
      for (std::uint32_t z = box.lo.z; z <= std::min(box.hi.z, n - 1); ++z)
        keys.push_back(NaiveKey(level, {x, y, z}));
  std::sort(keys.begin(), keys.end());
  return keys;
}

TEST(CoveringRanges, ExactCoverEqualsBruteForce) {
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 3000; ++trial) {
    const int level = static_cast<int>(rng() % 6);
    const std::uint32_t n = 1u << level;
    auto pick = [&](std::uint32_t& lo, std::uint32_t& hi) {
      lo = static_cast<std::uint32_t>(rng() % (n + 1));  // may start past the grid
      hi = lo + static_cast<std::uint32_t>(rng() % (n + 2));  // may end past the grid
      if (lo > n - 1 && rng() % 2) lo = n - 1;
    };
    CellBox box;
    pick(box.lo.x, box.hi.x);
    pick(box.lo.y, box.hi.y);
    pick(box.lo.z, box.hi.z);
    const auto ranges = CoveringRanges(level, box);
    std::vector<std::uint64_t> covered;
    for (std::size_t i = 0; i < ranges.size(); ++i) {
      ASSERT_LE(ranges[i].first, ranges[i].last);
      if (i > 0) {
        ASSERT_GT(ranges[i].first, ranges[i - 1].last + 1) << "adjacent ranges must be merged";
      }
      for (std::uint64_t v = ranges[i].first; v <= ranges[i].last; ++v) covered.push_back(v);
    }
    ASSERT_EQ(covered, NaiveCover(level, box)) << "trial " << trial << " level " << level;
  }
}

TEST(CoveringRanges, BoundedCoverIsASupersetWithFewRanges) {
  std::mt19937_64 rng(11);
  for (int trial = 0; trial < 300; ++trial) {
    const int level = 5;
    CellBox box{{static_cast<std::uint32_t>(rng() % 20), static_cast<std::uint32_t>(rng() % 20),
                 static_cast<std::uint32_t>(rng() % 20)},
                {}};
    box.hi = {box.lo.x + static_cast<std::uint32_t>(rng() % 12), box.lo.y + static_cast<std::uint32_t>(rng() % 12),
              box.lo.z + static_cast<std::uint32_t>(rng() % 12)};
    const std::size_t max_ranges = 1 + rng() % 8;
    const auto ranges = CoveringRanges(level, box, max_ranges);
    ASSERT_LE(ranges.size(), max_ranges);
    for (std::uint64_t key : NaiveCover(level, box)) {
      const bool inside = std::any_of(ranges.begin(), ranges.end(),
                                      [&](const KeyRange& r) { return key >= r.first && key <= r.last; });
      ASSERT_TRUE(inside);
    }
  }
  EXPECT_THROW(CoveringRanges(22, {}), Error);
  EXPECT_THROW(CoveringRanges(3, {}, 0), Error);
}

TEST(CoveringRanges, DeepLevelsStaySmall) {
  // A box aligned to a level-10 node at level 21 is one range.
  const NodeKey node = NodeKey::FromCell(10, {5, 900, 17});
  const std::uint32_t s = 1u << 11;
  const CellBox box{{5 * s, 900 * s, 17 * s}, {6 * s - 1, 901 * s - 1, 18 * s - 1}};
  const auto ranges = CoveringRanges(kMaxLevel, box);
  ASSERT_EQ(ranges.size(), 1u);
  EXPECT_EQ(ranges[0], node.DescendantRange(kMaxLevel));
}

}  // namespace
}  // namespace octocosm
