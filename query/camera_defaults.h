// The defaults of a camera, scaled to a dataset's cube: where it looks, how
// near and far it sees, and where it stands to see the whole cube. Shared by
// the command-line camera flags and the Python module.
#pragma once

#include <array>

#include "index/cube.h"

namespace octocosm {

std::array<double, 3> CubeCentre(const Cube& cube);

// A millionth of the cube's edge.
double DefaultNear(const Cube& cube);

// The camera's distance to the cube's centre plus the cube's edge, so that
// nothing in the cube is clipped from wherever the camera is, inside the
// cube or out.
double DefaultFar(const std::array<double, 3>& position, const Cube& cube);

// A position from which the whole cube is in view: on the +z side of its
// centre, far enough that the cube's bounding sphere fits the vertical field
// of view.
std::array<double, 3> OverviewPosition(const Cube& cube, double fov_y_degrees);

}  // namespace octocosm
