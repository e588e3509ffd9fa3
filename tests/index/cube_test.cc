// Cube geometry at the edges: faces, periodic wrap, degenerate boxes, large
// offsets, and the prefix property that keeps levels consistent.
#include "index/cube.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "base/error.h"

namespace octocosm {
namespace {

TEST(Cube, CellsOfInteriorPoints) {
  const Cube cube{{-1, 0, 10}, 4, false};
  const double p[3] = {0.5, 3.9, 10.1};  // t = 0.375, 0.975, 0.025
  EXPECT_EQ(cube.CellOf(p, 0), (CellCoord{0, 0, 0}));
  EXPECT_EQ(cube.CellOf(p, 1), (CellCoord{0, 1, 0}));
  EXPECT_EQ(cube.CellOf(p, 3), (CellCoord{3, 7, 0}));
  EXPECT_EQ(cube.LeafKey(p, 3), NodeKey::FromCell(3, {3, 7, 0}));
  EXPECT_EQ(cube.ChildOctant(p, 0), 2);  // y in the upper half only
}

TEST(Cube, FacesGoToTheCellAbove_UpperFaceToTheLast) {
  const Cube cube{{0, 0, 0}, 8, false};
  const double lower[3] = {0, 0, 0};
  const double on_face[3] = {4, 2, 1};
  const double upper[3] = {8, 8, 8};
  for (int level = 0; level <= kMaxLevel; ++level) {
    const std::uint32_t last = (1u << level) - 1;
    EXPECT_EQ(cube.CellOf(lower, level), (CellCoord{0, 0, 0}));
    EXPECT_EQ(cube.CellOf(upper, level), (CellCoord{last, last, last})) << level;
  }
  EXPECT_EQ(cube.CellOf(on_face, 1), (CellCoord{1, 0, 0}));
  EXPECT_EQ(cube.CellOf(on_face, 3), (CellCoord{4, 2, 1}));
}

// A point exactly on an inner cell face belongs to the cell above, whatever
// the cube's size: the sizes here are not powers of two (a product with a
// rounded 1 / size put about 2% of such points into the cell below), with
// the lower corner at zero and far from it.
TEST(Cube, PointsExactlyOnInnerFacesGoToTheCellAboveInAnyCube) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> mantissa(0.5, 1);
  int checked = 0;
  for (int trial = 0; trial < 400; ++trial) {
    // 24-bit mantissas (float32 sizes, as many snapshots have) make most faces exact.
    const double size = std::ldexp(std::round(std::ldexp(mantissa(rng), 24)), static_cast<int>(rng() % 40) - 34);
    for (const double origin : {0.0, -1e6, 3.5e8}) {
      const Cube cube{{origin, origin, origin}, size, false};
      for (int level = 1; level <= kMaxLevel; ++level) {
        const std::uint64_t k = 1 + rng() % ((std::uint64_t{1} << level) - 1);
        // The face k * size / 2^L, taken only where the coordinate and its
        // difference from the origin are exact (else no point lies on it).
        const double product = static_cast<double>(k) * size;
        const double offset = std::ldexp(product, -level);
        const double x = origin + offset;
        if (std::fma(static_cast<double>(k), size, -product) != 0 || x - origin != offset) continue;
        const double p[3] = {x, origin, x};
        const CellCoord c = cube.CellOf(p, level);
        ASSERT_EQ(c.x, k) << "size " << size << " origin " << origin << " level " << level;
        ASSERT_EQ(c.y, 0u);
        ASSERT_EQ(c.z, k);
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 5000);
}

TEST(Cube, PointsSlightlyOutsideAreClampedNeverOutOfRange) {
  const Cube cube{{0, 0, 0}, 1, false};
  const double below[3] = {-1e-17, -1e-300, -0.0};
  const double above[3] = {std::nextafter(1.0, 2.0), 1 + 1e-9, 1e300};
  const double nan[3] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                         -std::numeric_limits<double>::infinity()};
  for (int level = 0; level <= kMaxLevel; ++level) {
    const std::uint32_t last = (1u << level) - 1;
    EXPECT_EQ(cube.CellOf(below, level), (CellCoord{0, 0, 0}));
    EXPECT_EQ(cube.CellOf(above, level), (CellCoord{last, last, last}));
    const CellCoord c = cube.CellOf(nan, level);
    EXPECT_EQ(c.x, 0u);
    EXPECT_EQ(c.y, last);
    EXPECT_EQ(c.z, 0u);
  }
  const auto g = cube.GridCoords(above, Cube::kMaxGridBits);
  EXPECT_EQ(g[0], (std::uint64_t{1} << Cube::kMaxGridBits) - 1);
}

TEST(Cube, PeriodicWrapsIntoTheBox) {
  const Cube cube{{0, 0, 0}, 100, true};
  const double on_upper_face[3] = {100, 100, 100};
  const double outside[3] = {-25, 125, 230};  // wrap to 75, 25, 30
  const double just_below[3] = {-1e-13, 50, 50};
  EXPECT_EQ(cube.CellOf(on_upper_face, 2), (CellCoord{0, 0, 0}));
  EXPECT_EQ(cube.CellOf(outside, 2), (CellCoord{3, 1, 1}));
  EXPECT_EQ(cube.CellOf(just_below, 4), (CellCoord{15, 8, 8}));
  // Much smaller than an ulp of 1: the wrap gives exactly 1, which clamps.
  const double tiny_below[3] = {-1e-300, 0, 0};
  EXPECT_EQ(cube.CellOf(tiny_below, 21).x, (1u << 21) - 1);
}

TEST(Cube, DeeperCellsRefineShallowerOnesExactly) {
  std::mt19937_64 rng(7);
  const Cube cube{{1e9, -3e9, 0.5}, 1234.5678, false};
  std::uniform_real_distribution<double> u(-0.01, 1.01);
  for (int trial = 0; trial < 20000; ++trial) {
    double p[3];
    for (int a = 0; a < 3; ++a) p[a] = cube.origin[a] + u(rng) * cube.size;
    if (trial % 5 == 0) p[0] = cube.origin[0] + cube.size * std::ldexp(std::floor(u(rng) * 64), -6);  // on faces
    const NodeKey leaf = cube.LeafKey(p, kMaxLevel);
    const auto fine = cube.GridCoords(p, kMaxLevel + 16);
    for (int level = 0; level <= kMaxLevel; ++level) {
      ASSERT_EQ(cube.LeafKey(p, level), leaf.AncestorAt(level));
      ASSERT_TRUE(cube.Holds(leaf.AncestorAt(level), p));
      if (level < kMaxLevel) {
        ASSERT_EQ(cube.ChildOctant(p, level), leaf.AncestorAt(level + 1).OctantInParent());
      }
    }
    const CellCoord c = leaf.cell();
    ASSERT_EQ(fine[0] >> 16, c.x);
    ASSERT_EQ(fine[1] >> 16, c.y);
    ASSERT_EQ(fine[2] >> 16, c.z);
  }
}

TEST(Cube, NodeCubeContainsItsPoints) {
  const Cube cube{{-5, -5, -5}, 10, false};
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-5, 5);
  for (int trial = 0; trial < 2000; ++trial) {
    const double p[3] = {u(rng), u(rng), u(rng)};
    for (int level : {0, 1, 5, 13, 21}) {
      const NodeCube node = cube.NodeCubeOf(cube.LeafKey(p, level));
      EXPECT_DOUBLE_EQ(node.size, std::ldexp(10.0, -level));
      for (int a = 0; a < 3; ++a) {
        EXPECT_LE(node.origin[a], p[a]);
        EXPECT_GE(node.origin[a] + node.size, p[a]);
      }
    }
  }
}

TEST(Cube, FromBoundsPutsTheMaxPointStrictlyInside) {
  const Cube cube = Cube::FromBounds({0, -2, 1}, {3, 1, 1.5});
  EXPECT_GT(cube.size, 3.0);
  EXPECT_LT(cube.size, 3.0001);
  const double hi[3] = {3, 1, 1.5};
  const auto g = cube.GridCoords(hi, Cube::kMaxGridBits);
  EXPECT_LT(g[0], (std::uint64_t{1} << Cube::kMaxGridBits) - 1);  // not clamped
  EXPECT_LT((hi[0] - cube.origin[0]) / cube.size, 1.0);
}

TEST(Cube, FromBoundsOfCoincidentPointsHasTinyNonZeroSize) {
  for (double at : {0.0, 1.0, -7.5e-3, 1e9, -4e15}) {
    const Cube cube = Cube::FromBounds({at, at, at}, {at, at, at});
    EXPECT_GT(cube.size, 0) << at;
    EXPECT_LT(cube.size, std::max(1.0, std::fabs(at)) * 1e-9) << at;
    EXPECT_GT(cube.origin[0] + cube.size, at) << at;  // representable: the point is strictly inside
    cube.Validate();
    const double p[3] = {at, at, at};
    EXPECT_EQ(cube.CellOf(p, 21), (CellCoord{0, 0, 0}));
  }
}

TEST(Cube, LargeOffsetWithSmallBox) {
  // A 1-unit box a billion units from the origin: every level still resolves
  // (cells 2^-21 wide are 4 ulps of 1e9), and the differences x - origin are
  // exact, so the cells are exactly those of the unit offsets.
  const Cube cube = Cube::FromBounds({1e9, 1e9, 1e9}, {1e9 + 1, 1e9 + 0.5, 1e9 + 0.25});
  const double hi[3] = {1e9 + 1, 1e9 + 0.5, 1e9 + 0.25};
  const double mid[3] = {1e9 + 0.5, 1e9 + 0.25, 1e9 + 0.125};
  EXPECT_EQ(cube.CellOf(hi, 21).x, static_cast<std::uint32_t>(std::floor(1.0 / cube.size * (1 << 21))));
  EXPECT_LT(cube.CellOf(hi, 21).x, (1u << 21) - 1);  // strictly inside: not clamped
  const CellCoord c = cube.CellOf(mid, 1);
  EXPECT_EQ(c, (CellCoord{0, 0, 0}));  // just below the half of a slightly enlarged cube
  EXPECT_EQ(cube.CellOf(mid, 21).x, static_cast<std::uint32_t>(std::floor(0.5 / cube.size * (1 << 21))));
}

TEST(Cube, ValidateAndFromBoundsRejectBadInput) {
  EXPECT_THROW((Cube{{0, 0, 0}, 0, false}.Validate()), Error);
  EXPECT_THROW((Cube{{0, 0, 0}, -1, false}.Validate()), Error);
  EXPECT_THROW((Cube{{0, std::nan(""), 0}, 1, false}.Validate()), Error);
  EXPECT_THROW((Cube{{0, 0, 0}, std::numeric_limits<double>::infinity(), false}.Validate()), Error);
  EXPECT_THROW(Cube::FromBounds({0, 0, 0}, {1, -1, 1}), Error);
  EXPECT_THROW(Cube::FromBounds({0, 0, std::nan("")}, {1, 1, 1}), Error);
  try {
    Cube::FromBounds({0, 0, 0}, {1, -1, 1});
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
  }
}

}  // namespace
}  // namespace octocosm
