// Query regions: which points a query keeps, and which octree nodes it may
// skip without reading them.
//
// Contains(point) is the exact test applied to every decoded point;
// MayIntersect(node cube) is a conservative test used to cull nodes: it may
// say true for a node with no point in the region, never false for a node
// with one. A query's result is therefore exactly "the points of the selected
// nodes for which Contains is true", whatever the culling does.
//
// Periodic datasets (Cube::periodic): boxes and spheres are periodic, i.e. a
// point is inside when any of its periodic images is; a box or sphere that
// straddles a face of the simulation box also selects the points near the
// opposite face, and a box at least as wide as the simulation box on an axis
// covers that whole axis. Points keep their stored coordinates (in
// [origin, origin + size)); they are not shifted next to the region. Frusta
// are never periodic: a camera sees the stored coordinates.
//
// Non-periodic datasets: a region that extends past the cube just selects
// what is inside the cube.
#pragma once

#include <array>
#include <memory>

#include "index/cube.h"
#include "query/frustum.h"

namespace octocosm {

class Region {
 public:
  virtual ~Region() = default;
  virtual bool Contains(const double* point) const = 0;
  virtual bool MayIntersect(const NodeCube& node) const = 0;
};

// The closed box lo <= p <= hi. Throws Error::InvalidArgument for non-finite
// bounds or lo > hi on an axis.
std::unique_ptr<Region> MakeBoxRegion(const std::array<double, 3>& lo, const std::array<double, 3>& hi, const Cube& cube);
// The closed ball |p - center| <= radius (minimal-image distance when
// periodic). Throws Error::InvalidArgument for a non-finite center or a
// radius that is negative or not finite.
std::unique_ptr<Region> MakeSphereRegion(const std::array<double, 3>& center, double radius, const Cube& cube);
// The points inside all six planes.
std::unique_ptr<Region> MakeFrustumRegion(const Frustum& frustum);
// Every point (a query of a whole level).
std::unique_ptr<Region> MakeEverythingRegion();

}  // namespace octocosm
