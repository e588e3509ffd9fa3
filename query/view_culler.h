// What a view may see of an octree: its frustum test on node cubes grown by a
// margin — the farthest time interpolation moves a point out of its node,
// plus, where the caller knows it, how far the points' blobs reach beyond
// their cube. In a periodic cube a moved point past a face is drawn at its
// image inside, near the opposite face, so the part of a grown cube beyond a
// face is tested there too.
#pragma once

#include <array>
#include <cstdint>
#include <optional>

#include "index/cube.h"
#include "query/frustum.h"

namespace octocosm {

class ViewCuller {
 public:
  // Sees everything: no view to cull by.
  ViewCuller() = default;
  // `margin` >= 0, in world units.
  ViewCuller(const Camera& camera, const Cube& cube, double margin);

  // False only when the cube, grown by the margin and `reach`, lies wholly
  // outside the view (and so do its periodic images).
  bool MayMeet(const NodeCube& c, double reach = 0) const;
  // Bit o set when octant o of `c` (Cube::ChildOctant order: x, y, z bits),
  // grown by the margin and `reach[o]`, may meet the view. A cube wholly in
  // view needs no test per octant: 0xFF.
  std::uint8_t OctantsInView(const NodeCube& c, const std::array<double, 8>& reach) const;

 private:
  bool MayMeetBox(const std::array<double, 3>& lo, const std::array<double, 3>& hi) const;

  std::optional<Frustum> frustum_;
  Cube cube_;
  double margin_ = 0;
};

}  // namespace octocosm
