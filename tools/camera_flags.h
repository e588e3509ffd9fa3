// The camera flags shared by `octocosm query`, `render` and `view`: a
// position, look-at point and up direction, or an OpenGL view matrix, plus
// field of view and near/far distances, with defaults scaled to the dataset's
// cube.
#pragma once

#include <optional>
#include <string>

#include "index/cube.h"
#include "query/camera_defaults.h"
#include "query/frustum.h"

namespace CLI {
class App;
}

namespace octocosm {

struct CameraFlags {
  std::string position, look_at, up = "0,1,0", view_matrix;
  double fov = 60, near = 0, far = 0;

  bool given() const { return !position.empty() || !view_matrix.empty(); }
};

// Registers --camera, --look-at, --up, --view-matrix, --fov, --near, --far.
void AddCameraFlags(CLI::App& command, CameraFlags& flags);

// The camera the flags describe for `cube` and `aspect` (width / height).
// Defaults: look at the cube's centre; near a millionth of the cube; far the
// camera's distance to the centre plus the cube's edge. Without --camera or
// --view-matrix, `fallback_position` is used when given, else it is an error.
// Throws Error::InvalidArgument naming the camera flags.
Camera CameraFromFlags(const CameraFlags& flags, const Cube& cube, double aspect,
                       const std::optional<std::array<double, 3>>& fallback_position = std::nullopt);

// Sets the near and far distances of a camera that moves (camera paths, the
// viewer) as CameraFromFlags does for a fixed one: --near and --far when
// given, else a millionth of the cube and the camera's distance to the
// cube's centre plus its edge, so that nothing in the cube is clipped from
// wherever the camera is, inside the cube or out.
void ApplyDepthRange(const CameraFlags& flags, const Cube& cube, Camera& camera);

}  // namespace octocosm
