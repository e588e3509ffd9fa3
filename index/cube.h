// The dataset cube and the geometry of node cubes inside it.
//
// The octree divides one axis-aligned cube, the dataset cube (origin, edge
// `size`), into 2^L x 2^L x 2^L cells at level L; node key (L, cell) covers
//
//   [origin + cell * size / 2^L, origin + (cell + 1) * size / 2^L)   per axis.
//
// Every placement of a point (its cell at a level, its child octant, its
// quantized position inside a node block, its fine density cell) goes through
// one function, GridCoords, so that they can never disagree with each other:
//
//   t    = (x - origin) / size                  the point's unit coordinate
//   t    = t - floor(t)                         only in a periodic cube
//   grid = clamp(floor(t * 2^bits), 0, 2^bits - 1)
//
// The division is correctly rounded, so a point exactly on a cell face (t
// exactly a multiple of 2^-bits) goes to the cell above it in any cube.
// Multiplying by 2^bits is exact in binary floating point, so the grid
// coordinate at `bits` is exactly the grid coordinate at `bits + k` shifted
// right by k: a point's cell at level L is the prefix of its cell at every
// deeper level, and a node's children partition its points exactly, even for
// points on a cell face.
//
// Edges, stated once:
//  - A point on the upper face (x == origin + size) goes to the last cell.
//  - In a non-periodic cube a point outside the cube (by a rounding error,
//    say) goes to the nearest edge cell; callers are expected to choose a cube
//    that contains their points (FromBounds does).
//  - In a periodic cube (a simulation box of edge `size`) points are first
//    wrapped into [origin, origin + size): x == origin + size maps to the first
//    cell, x == origin - 1e-20 to the last.
//  - NaN goes to cell 0 (never an out-of-range index); the subtree builder
//    rejects non-finite positions before they get here.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "index/morton.h"

namespace octocosm {

// The finest grid anything is placed on: kMaxLevel levels of cells plus the
// 16 bits of a quantized position inside a block. Because a point's
// coordinates at fewer bits are its coordinates here shifted right (see
// above), its GridPoint, computed once, gives its cell at every level, its
// child octant, its quantized position inside any node and its fine density
// cell, each by a shift: the octree builder computes it once per particle
// instead of placing the particle again at every level.
inline constexpr int kFinestGridBits = kMaxLevel + 16;
using GridPoint = std::array<std::uint64_t, 3>;

// The point's coordinates on the 2^bits grid (bits <= kFinestGridBits):
// exactly Cube::GridCoords(point, bits).
inline std::uint64_t GridAxisAt(const GridPoint& grid, int axis, int bits) {
  return grid[static_cast<std::size_t>(axis)] >> (kFinestGridBits - bits);
}

// Which child of the node at `level` holds the point: Cube::ChildOctant.
inline int OctantAt(const GridPoint& grid, int level) {
  const int shift = kFinestGridBits - 1 - level;
  return static_cast<int>(((grid[0] >> shift) & 1) | (((grid[1] >> shift) & 1) << 1) | (((grid[2] >> shift) & 1) << 2));
}

// Whether the point lies in node `key`: Cube::Holds.
inline bool GridHolds(const GridPoint& grid, NodeKey key) {
  const int level = key.level();
  const CellCoord cell = key.cell();
  return GridAxisAt(grid, 0, level) == cell.x && GridAxisAt(grid, 1, level) == cell.y &&
         GridAxisAt(grid, 2, level) == cell.z;
}

// The cube of one node, in absolute coordinates.
struct NodeCube {
  std::array<double, 3> origin{};
  double size = 0;
};

struct Cube {
  std::array<double, 3> origin{0, 0, 0};
  double size = 1;
  bool periodic = false;

  // The most bits GridCoords accepts: t * 2^bits must stay an exact integer
  // below 2^53. Level 21 plus the 16 bits of a quantized position is 37.
  static constexpr int kMaxGridBits = 48;

  // The cube whose lower corner is `lo` and whose edge is the largest extent
  // of the box [lo, hi], enlarged by a small margin so that `hi` lies strictly
  // inside (t < 1 on every axis). When all points coincide the edge is a tiny
  // non-zero size. Not periodic. Throws Error::InvalidArgument when a bound is
  // not finite or hi < lo on some axis.
  static Cube FromBounds(const std::array<double, 3>& lo, const std::array<double, 3>& hi);

  // Throws Error::InvalidArgument unless origin is finite and size is finite and > 0.
  void Validate() const;

  // Edge of a node at `level` (exact: size * 2^-level).
  double NodeSize(int level) const;
  NodeCube NodeCubeOf(NodeKey key) const;

  // The point's coordinates on a 2^bits grid over the cube, as described
  // above. Precondition: 0 <= bits <= kMaxGridBits. Never out of range.
  std::array<std::uint64_t, 3> GridCoords(const double* point, int bits) const;
  GridPoint FinestGridCoords(const double* point) const { return GridCoords(point, kFinestGridBits); }
  // The point's cell at `level` (0..kMaxLevel).
  CellCoord CellOf(const double* point, int level) const;
  // The key of the node at `level` that holds the point.
  NodeKey LeafKey(const double* point, int level) const;
  // Which child of the node at `level` holds the point: the low bits of its
  // cell at level + 1 (x0 | y0 << 1 | z0 << 2). Valid also at kMaxLevel (the
  // octant inside a deepest node, used to order its points).
  int ChildOctant(const double* point, int level) const;
  // In a periodic cube, moves the point into [origin, origin + size) on every
  // axis (its image there): where ingest stores it. A coordinate already
  // inside is left exactly as it is (dividing and multiplying by the size
  // would move it by an ulp, and a store would depend on which chunk a
  // point arrived in). No effect otherwise.
  void Wrap(double* point) const;
  // Whether the point belongs to `key` (its cell at key.level() is key.cell()).
  bool Holds(NodeKey key, const double* point) const;
};

// ---- Inline: GridCoords runs once or more per particle in every pass of
// ingest, and inlined into those loops the divisions of successive points
// overlap.

namespace cube_detail {
// floor(x), without the libm call that std::floor is on baseline x86-64 (no
// SSE4.1 rounding instruction): truncation, corrected below zero, where it
// is exact (|x| < 2^52); std::floor elsewhere, NaN included.
inline double Floor(double x) {
  if (!(std::fabs(x) < 0x1p52)) return std::floor(x);
  const double truncated = static_cast<double>(static_cast<std::int64_t>(x));
  return truncated > x ? truncated - 1 : truncated;
}
}  // namespace cube_detail

inline std::array<std::uint64_t, 3> Cube::GridCoords(const double* point, int bits) const {
  const std::uint64_t last = (std::uint64_t{1} << bits) - 1;
  const double cells = static_cast<double>(last + 1);  // exact: bits <= kMaxGridBits < 53
  std::array<std::uint64_t, 3> grid{};
  for (int a = 0; a < 3; ++a) {
    // A division, not a product with 1 / size: the rounded reciprocal put
    // about one point in fifty that lies exactly on a cell face of a cube
    // whose size is not a power of two into the cell below (x = 389.97988...
    // at the midplane of a cube of edge 779.95977...), against the half-open
    // cells of cube.h and against every other octree (PCL's keys are
    // divisions too). It costs under 2 ns a call.
    double t = (point[a] - origin[a]) / size;
    // Inside the box already (the usual case), t - Floor(t) is t.
    if (periodic && !(t >= 0 && t < 1)) t -= cube_detail::Floor(t);
    const double scaled = t * cells;
    // floor(scaled) > 0 exactly when scaled >= 1, floor(scaled) >= cells
    // exactly when scaled >= cells, and in between truncation is floor.
    // Written so that NaN fails the first test: no float-to-int conversion
    // of an out-of-range value, which would be undefined behaviour.
    if (!(scaled >= 1)) {
      grid[a] = 0;
    } else if (scaled >= cells) {
      grid[a] = last;
    } else {
      grid[a] = static_cast<std::uint64_t>(scaled);
    }
  }
  return grid;
}

inline CellCoord Cube::CellOf(const double* point, int level) const {
  const auto g = GridCoords(point, level);
  return {static_cast<std::uint32_t>(g[0]), static_cast<std::uint32_t>(g[1]), static_cast<std::uint32_t>(g[2])};
}

inline NodeKey Cube::LeafKey(const double* point, int level) const { return NodeKey::FromCell(level, CellOf(point, level)); }

}  // namespace octocosm
