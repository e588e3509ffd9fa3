#include "query/view_culler.h"

#include <algorithm>

namespace octocosm {

ViewCuller::ViewCuller(const Camera& camera, const Cube& cube, double margin)
    : frustum_(Frustum::FromCamera(camera)), cube_(cube), margin_(margin) {}

bool ViewCuller::MayMeetBox(const std::array<double, 3>& lo, const std::array<double, 3>& hi) const {
  if (!frustum_) return true;
  if (!cube_.periodic || margin_ <= 0) return frustum_->MayIntersectBox(lo, hi);
  // Per axis, the shifts worth trying: none, and one box length towards the
  // inside for each face the grown cube crosses (each axis on its own, so a
  // corner's images are all tried).
  std::array<std::array<double, 3>, 3> shifts{};
  std::array<std::size_t, 3> count{};
  for (std::size_t a = 0; a < 3; ++a) {
    shifts[a][count[a]++] = 0;
    if (lo[a] < cube_.origin[a]) shifts[a][count[a]++] = cube_.size;
    if (hi[a] > cube_.origin[a] + cube_.size) shifts[a][count[a]++] = -cube_.size;
  }
  for (std::size_t x = 0; x < count[0]; ++x) {
    for (std::size_t y = 0; y < count[1]; ++y) {
      for (std::size_t z = 0; z < count[2]; ++z) {
        const std::array<double, 3> shift = {shifts[0][x], shifts[1][y], shifts[2][z]};
        if (frustum_->MayIntersectBox({lo[0] + shift[0], lo[1] + shift[1], lo[2] + shift[2]},
                                      {hi[0] + shift[0], hi[1] + shift[1], hi[2] + shift[2]})) {
          return true;
        }
      }
    }
  }
  return false;
}

bool ViewCuller::MayMeet(const NodeCube& c, double reach) const {
  const double m = margin_ + reach;
  return MayMeetBox({c.origin[0] - m, c.origin[1] - m, c.origin[2] - m},
                    {c.origin[0] + c.size + m, c.origin[1] + c.size + m, c.origin[2] + c.size + m});
}

std::uint8_t ViewCuller::OctantsInView(const NodeCube& c, const std::array<double, 8>& reach) const {
  if (!frustum_) return 0xFF;
  const double m = margin_ + *std::max_element(reach.begin(), reach.end());
  // Wholly in view with the largest reach: every octant is (its images
  // need no test).
  if (frustum_->ContainsBox({c.origin[0] - m, c.origin[1] - m, c.origin[2] - m},
                            {c.origin[0] + c.size + m, c.origin[1] + c.size + m, c.origin[2] + c.size + m})) {
    return 0xFF;
  }
  std::uint8_t mask = 0;
  const double half = c.size / 2;
  for (int o = 0; o < 8; ++o) {
    NodeCube octant{c.origin, half};
    for (int a = 0; a < 3; ++a) octant.origin[a] += ((o >> a) & 1) ? half : 0;
    if (MayMeet(octant, reach[static_cast<std::size_t>(o)])) mask |= static_cast<std::uint8_t>(1u << o);
  }
  return mask;
}

}  // namespace octocosm
