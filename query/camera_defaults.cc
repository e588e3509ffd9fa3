#include "query/camera_defaults.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace octocosm {

std::array<double, 3> CubeCentre(const Cube& cube) {
  return {cube.origin[0] + cube.size / 2, cube.origin[1] + cube.size / 2, cube.origin[2] + cube.size / 2};
}

double DefaultNear(const Cube& cube) { return cube.size * 1e-6; }

double DefaultFar(const std::array<double, 3>& position, const Cube& cube) {
  const auto c = CubeCentre(cube);
  double d2 = 0;
  for (int a = 0; a < 3; ++a) d2 += (position[a] - c[a]) * (position[a] - c[a]);
  return std::sqrt(d2) + cube.size;
}

std::array<double, 3> OverviewPosition(const Cube& cube, double fov_y_degrees) {
  const double radius = cube.size * std::sqrt(3.0) / 2;
  const double half_fov = std::clamp(fov_y_degrees, 1.0, 179.0) * std::numbers::pi / 360;
  auto p = CubeCentre(cube);
  p[2] += radius / std::sin(half_fov) * 1.02;
  return p;
}

}  // namespace octocosm
