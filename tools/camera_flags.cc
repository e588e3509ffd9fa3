#include "tools/camera_flags.h"

#include <algorithm>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "query/camera_defaults.h"
#include "tools/cli_util.h"

namespace octocosm {
namespace {

std::array<double, 3> Triple(const std::string& text, const std::string& flag) {
  const std::vector<double> v = ParseNumberList(text, flag);
  if (v.size() != 3) throw Error::InvalidArgument(flag + " '" + text + "': expected 3 numbers x,y,z");
  return {v[0], v[1], v[2]};
}

Camera Build(const CameraFlags& f, const Cube& cube, double aspect,
             const std::optional<std::array<double, 3>>& fallback_position) {
  // Defaults scaled to the data: near a millionth of the cube, far beyond its far side.
  const double near = f.near > 0 ? f.near : DefaultNear(cube);
  if (!f.view_matrix.empty()) {
    if (!f.position.empty() || !f.look_at.empty()) {
      throw Error::InvalidArgument("--view-matrix replaces --camera and --look-at; give one or the other");
    }
    const std::vector<double> m = ParseNumberList(f.view_matrix, "--view-matrix");
    if (m.size() != 16) throw Error::InvalidArgument("--view-matrix: expected 16 numbers (column-major 4x4)");
    std::array<double, 16> view;
    std::copy(m.begin(), m.end(), view.begin());
    const Camera probe = Camera::FromViewMatrix(view, f.fov, aspect, near, near * 2);
    return Camera::FromViewMatrix(view, f.fov, aspect, near, f.far > 0 ? f.far : DefaultFar(probe.position, cube));
  }
  if (f.position.empty() && !fallback_position) {
    throw Error::InvalidArgument("--camera x,y,z (or --view-matrix) is required here");
  }
  Camera camera;
  camera.position = f.position.empty() ? *fallback_position : Triple(f.position, "--camera");
  camera.look_at = f.look_at.empty() ? CubeCentre(cube) : Triple(f.look_at, "--look-at");
  camera.up = Triple(f.up, "--up");
  camera.fov_y_degrees = f.fov;
  camera.aspect = aspect;
  ApplyDepthRange(f, cube, camera);
  camera.Validate();
  return camera;
}

}  // namespace

void AddCameraFlags(CLI::App& command, CameraFlags& flags) {
  command.add_option("--camera", flags.position, "camera position x,y,z");
  command.add_option("--look-at", flags.look_at, "point the camera looks at (default: the cube's centre)");
  command.add_option("--up", flags.up, "up direction")->default_val("0,1,0");
  command.add_option("--view-matrix", flags.view_matrix, "OpenGL view matrix, 16 numbers column-major (replaces --camera/--look-at/--up)");
  command.add_option("--fov", flags.fov, "vertical field of view, degrees")->default_val(60);
  command.add_option("--near", flags.near, "near distance (default: cube size * 1e-6)");
  command.add_option("--far", flags.far, "far distance (default: beyond the cube's far side)");
}

Camera CameraFromFlags(const CameraFlags& flags, const Cube& cube, double aspect,
                       const std::optional<std::array<double, 3>>& fallback_position) {
  try {
    return Build(flags, cube, aspect, fallback_position);
  } catch (const Error& e) {
    if (e.kind() != ErrorKind::kInvalidArgument) throw;
    std::string what = e.what();
    const std::string prefix = "invalid argument: ";
    if (what.rfind(prefix, 0) == 0) what.erase(0, prefix.size());
    throw Error::InvalidArgument("camera flags (--camera, --look-at, --up, --view-matrix, --fov, --near, --far): " + what);
  }
}

void ApplyDepthRange(const CameraFlags& flags, const Cube& cube, Camera& camera) {
  camera.near = flags.near > 0 ? flags.near : DefaultNear(cube);
  camera.far = flags.far > 0 ? flags.far : DefaultFar(camera.position, cube);
}

}  // namespace octocosm
