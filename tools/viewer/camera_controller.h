// The viewer's camera, moved by the mouse and keyboard: orbit about a pivot
// or fly. Pure arithmetic in double precision (the renderer takes a Camera in
// double, query/frustum.h); no window, no GL, so tests drive it directly.
//
// State: a position, a viewing direction given by yaw and pitch about the
// world's up direction (the --up of the starting camera), and the distance
// to the pivot straight ahead, so that pivot = position + forward * distance.
// Both modes share it, and switching between them keeps the view.
//
//   orbit  drag: turn the view about the pivot (the pivot stays in the
//          centre of the picture, the distance stays); scroll: move towards
//          or away from the pivot; right or middle drag: pan (camera and
//          pivot move together, the pivot follows the cursor).
//   fly    drag: turn the view about the camera (mouse look); W/S, A/D, E/Q
//          move forward/back, left/right, up/down along the world's up;
//          shift is faster; scroll changes the flying speed.
//
// In both modes a drag turns the viewing direction the way the cursor moves:
// right turns it right, down turns it down (orbiting, the camera thereby
// goes round the pivot to the left, or rises above it).
// Speeds scale with the dataset's cube, so a 1 Mpc and a 1 Gpc box handle
// the same.
#pragma once

#include <array>

#include <glm/vec3.hpp>

#include "query/frustum.h"

namespace octocosm {

enum class CameraMode { kOrbit, kFly };

const char* CameraModeName(CameraMode mode);  // "orbit", "fly"

// What moved the camera since the last frame. Drags and pans are in window
// pixels, x to the right and y downwards (as the mouse reports them).
struct CameraInput {
  double rotate_x = 0, rotate_y = 0;  // drag: orbit about the pivot, or look around
  double pan_x = 0, pan_y = 0;        // drag: move sideways
  double scroll = 0;                  // wheel notches, positive away from the user
  // Fly mode: -1, 0 or +1 along the camera's right (D/A), the world's up
  // (E/Q) and the viewing direction (W/S).
  std::array<int, 3> move{0, 0, 0};
  bool fast = false;  // shift held
  double seconds = 0; // since the last frame
};

class CameraController {
 public:
  // Radians turned per pixel dragged.
  static constexpr double kRadiansPerPixel = 0.005;
  // Orbit: each scroll notch divides the distance to the pivot by this.
  static constexpr double kZoomPerNotch = 1.15;
  // Fly: each scroll notch multiplies the speed by this; shift multiplies it by kFastFactor.
  static constexpr double kSpeedPerNotch = 1.25;
  static constexpr double kFastFactor = 5;
  // Fly: a quarter of the cube per second, at first.
  static constexpr double kFlySpeedPerCube = 0.25;
  // The pitch stays this far from straight up or down, so the viewing
  // direction never becomes parallel to up (an invalid camera).
  static constexpr double kPitchLimitRadians = 1.5607;  // 89.4 degrees

  // Starts at `camera` (its look-at point is the pivot) in orbit mode.
  // `cube_size` sets the speeds and the closest and farthest the orbit goes
  // (1e-6 to 1e3 cube edges from the pivot).
  CameraController(const Camera& camera, double cube_size);

  // Moves the camera. `viewport_height` (pixels) makes a pan of n pixels
  // move the pivot n pixels on the screen.
  void Update(const CameraInput& input, double viewport_height);
  // Jumps to `camera`, keeping the mode and the flying speed.
  void JumpTo(const Camera& camera);

  void set_mode(CameraMode mode) { mode_ = mode; }
  CameraMode mode() const { return mode_; }

  // The camera with this `aspect`; near and far are left at their defaults
  // for the caller to set (tools/camera_flags.h ApplyDepthRange).
  Camera camera(double aspect) const;
  std::array<double, 3> position() const { return {position_.x, position_.y, position_.z}; }
  std::array<double, 3> pivot() const;
  double distance() const { return distance_; }
  double fly_speed() const { return fly_speed_; }  // world units per second, without shift

 private:
  glm::dvec3 Forward() const;
  glm::dvec3 Right() const;
  void Turn(double dx, double dy);

  CameraMode mode_ = CameraMode::kOrbit;
  double cube_size_;
  glm::dvec3 up_{0, 1, 0};
  glm::dvec3 yaw_zero_{0, 0, -1};  // the horizontal direction of yaw 0
  glm::dvec3 position_{0, 0, 0};
  double yaw_ = 0, pitch_ = 0;
  double distance_ = 1;
  double fov_y_degrees_ = 60;
  double fly_speed_;
};

}  // namespace octocosm
