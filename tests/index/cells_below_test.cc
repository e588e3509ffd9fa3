// CellsBelow against the Morton keys it abbreviates (Cube::LeafKey), through
// its table (up to ten levels down) and past it, in plain and periodic cubes,
// including points on cell faces and outside the node.
#include "index/cells_below.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>

#include "base/error.h"

namespace octocosm {
namespace {

std::uint64_t ByKey(const Cube& cube, NodeKey node, int level, const double* p) {
  const std::uint64_t key = cube.LeafKey(p, level).value();
  const std::uint64_t first = node.DescendantRange(level).first;
  return key >= first && key - first < (std::uint64_t{1} << (3 * (level - node.level()))) ? key - first
                                                                                          : CellsBelow::kOutside;
}

TEST(CellsBelow, AgreesWithLeafKeysAtEveryDepth) {
  std::mt19937_64 random(5);
  for (const bool periodic : {false, true}) {
    const Cube cube{{-3.5, 10.0, 0.25}, 779.95977, periodic};
    for (const NodeKey node : {NodeKey::Root(), NodeKey::FromPath("r5"), NodeKey::FromPath("r0372")}) {
      const NodeCube box = cube.NodeCubeOf(node);
      std::uniform_real_distribution<double> inside(0, box.size);
      for (const int depth : {0, 1, 3, 6, 10, 11, 14}) {
        const int level = node.level() + depth;
        const CellsBelow cells(cube, node, level);
        EXPECT_EQ(cells.count(), std::uint64_t{1} << (3 * depth));
        for (int k = 0; k < 2000; ++k) {
          double p[3];
          for (int a = 0; a < 3; ++a) p[a] = box.origin[a] + inside(random);
          // Some points exactly on a face of the finest cells considered.
          if (k % 4 == 0) p[k % 3] = box.origin[k % 3] + std::ldexp(box.size, -depth) * (k % (1 << std::min(depth, 8)));
          const std::uint64_t cell = cells.Of(p);
          ASSERT_EQ(cell, ByKey(cube, node, level, p)) << "depth " << depth << " node " << node.Path();
          ASSERT_NE(cell, CellsBelow::kOutside);
        }
      }
    }
  }
}

TEST(CellsBelow, PointsOutsideTheNodeAreOutside) {
  const Cube cube{{0, 0, 0}, 64.0, false};
  const NodeKey node = NodeKey::FromPath("r3");  // x and y upper half, z lower half
  const CellsBelow cells(cube, node, node.level() + 2);
  const double inside[3] = {40, 40, 10};
  EXPECT_NE(cells.Of(inside), CellsBelow::kOutside);
  for (const auto& p : {std::array<double, 3>{10, 40, 10}, {40, 10, 10}, {40, 40, 40}, {31.999, 40, 10}}) {
    EXPECT_EQ(cells.Of(p.data()), CellsBelow::kOutside) << p[0] << " " << p[1] << " " << p[2];
  }
  // The node's lower face belongs to it; its upper face to the next node,
  // except at the cube's upper face.
  const double lower_face[3] = {32, 32, 0};
  EXPECT_EQ(cells.Of(lower_face), 0u);
  const double cube_face[3] = {64, 64, 31.9999};
  EXPECT_EQ(cells.Of(cube_face), cells.count() - 1);
}

TEST(CellsBelow, RejectsLevelsAboveTheNodeOrPastTheDeepest) {
  const Cube cube{{0, 0, 0}, 1.0, false};
  EXPECT_THROW(CellsBelow(cube, NodeKey::FromPath("r01"), 1), Error);
  EXPECT_THROW(CellsBelow(cube, NodeKey::Root(), kMaxLevel + 1), Error);
  EXPECT_NO_THROW(CellsBelow(cube, NodeKey::Root(), kMaxLevel));
}

}  // namespace
}  // namespace octocosm
