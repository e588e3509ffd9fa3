#include "index/cube.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "storage/error.h"

namespace octocosm {

Cube Cube::FromBounds(const std::array<double, 3>& lo, const std::array<double, 3>& hi) {
  double extent = 0;
  double scale = 0;
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(lo[a]) || !std::isfinite(hi[a]) || hi[a] < lo[a]) {
      throw Error::InvalidArgument("bounding box axis " + std::to_string(a) + " is [" + std::to_string(lo[a]) +
                                   ", " + std::to_string(hi[a]) + "]: bounds must be finite and lo <= hi");
    }
    extent = std::max(extent, hi[a] - lo[a]);
    scale = std::max({scale, std::fabs(lo[a]), std::fabs(hi[a])});
  }
  // The margin is relative to the extent (so the cube stays tight) but at
  // least a few hundred ulps of the coordinates (so origin + size is distinct
  // from hi far from zero) and never zero (all points coincident at 0).
  double margin = std::max({std::ldexp(extent, -20), std::ldexp(scale, -44), std::ldexp(1.0, -100)});
  Cube cube;
  cube.origin = lo;
  for (;;) {
    cube.size = extent + margin;
    bool inside = true;
    for (int a = 0; a < 3; ++a) {
      // The same arithmetic as GridCoords: hi must map to t < 1.
      if (!((hi[a] - lo[a]) / cube.size < 1.0)) inside = false;
    }
    if (inside) return cube;
    margin *= 2;
  }
}

void Cube::Validate() const {
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(origin[a])) {
      throw Error::InvalidArgument("cube origin axis " + std::to_string(a) + " is not finite");
    }
  }
  if (!std::isfinite(size) || !(size > 0)) {
    throw Error::InvalidArgument("cube size " + std::to_string(size) + " must be finite and > 0");
  }
}

double Cube::NodeSize(int level) const { return std::ldexp(size, -level); }

NodeCube Cube::NodeCubeOf(NodeKey key) const {
  const int level = key.level();
  const CellCoord cell = key.cell();
  const double s = NodeSize(level);
  return NodeCube{{origin[0] + cell.x * s, origin[1] + cell.y * s, origin[2] + cell.z * s}, s};
}

namespace {

// floor(x), without the libm call that std::floor is on baseline x86-64 (no
// SSE4.1 rounding instruction): truncation, corrected below zero, where it
// is exact (|x| < 2^52); std::floor elsewhere, NaN included.
double Floor(double x) {
  if (!(std::fabs(x) < 0x1p52)) return std::floor(x);
  const double truncated = static_cast<double>(static_cast<std::int64_t>(x));
  return truncated > x ? truncated - 1 : truncated;
}

}  // namespace

std::array<std::uint64_t, 3> Cube::GridCoords(const double* point, int bits) const {
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
    if (periodic) t -= Floor(t);
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

CellCoord Cube::CellOf(const double* point, int level) const {
  const auto g = GridCoords(point, level);
  return {static_cast<std::uint32_t>(g[0]), static_cast<std::uint32_t>(g[1]), static_cast<std::uint32_t>(g[2])};
}

NodeKey Cube::LeafKey(const double* point, int level) const { return NodeKey::FromCell(level, CellOf(point, level)); }

int Cube::ChildOctant(const double* point, int level) const {
  const auto g = GridCoords(point, level + 1);
  return static_cast<int>((g[0] & 1) | ((g[1] & 1) << 1) | ((g[2] & 1) << 2));
}

bool Cube::Holds(NodeKey key, const double* point) const { return LeafKey(point, key.level()) == key; }

void Cube::Wrap(double* point) const {
  if (!periodic) return;
  for (int a = 0; a < 3; ++a) {
    double t = (point[a] - origin[a]) / size;
    t -= std::floor(t);
    double x = origin[a] + t * size;
    if (x >= origin[a] + size) x = origin[a];  // t rounded up to 1
    point[a] = x;
  }
}

}  // namespace octocosm
