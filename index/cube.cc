#include "index/cube.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "base/error.h"

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


int Cube::ChildOctant(const double* point, int level) const {
  const auto g = GridCoords(point, level + 1);
  return static_cast<int>((g[0] & 1) | ((g[1] & 1) << 1) | ((g[2] & 1) << 2));
}

bool Cube::Holds(NodeKey key, const double* point) const { return LeafKey(point, key.level()) == key; }

void Cube::Wrap(double* point) const {
  if (!periodic) return;
  for (int a = 0; a < 3; ++a) {
    if (point[a] >= origin[a] && point[a] < origin[a] + size) continue;  // inside: exactly as it is
    double t = (point[a] - origin[a]) / size;
    t -= std::floor(t);
    double x = origin[a] + t * size;
    if (x >= origin[a] + size) x = origin[a];  // t rounded up to 1
    point[a] = x;
  }
}

}  // namespace octocosm
