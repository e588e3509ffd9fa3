#include "tools/viewer/camera_controller.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <glm/geometric.hpp>

namespace octocosm {
namespace {

glm::dvec3 Vec(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }

// The orbit stays between these multiples of the cube's edge from the pivot,
// and the flying speed between these many edges per second: beyond them
// float positions on the GPU (relative to nodes) or the user's patience give out.
constexpr double kMinDistancePerCube = 1e-6, kMaxDistancePerCube = 1e3;
constexpr double kMinSpeedPerCube = 1e-6, kMaxSpeedPerCube = 1e2;

}  // namespace

const char* CameraModeName(CameraMode mode) { return mode == CameraMode::kOrbit ? "orbit" : "fly"; }

CameraController::CameraController(const Camera& camera, double cube_size)
    : cube_size_(cube_size), fly_speed_(cube_size * kFlySpeedPerCube) {
  JumpTo(camera);
}

void CameraController::JumpTo(const Camera& camera) {
  up_ = glm::normalize(Vec(camera.up));
  position_ = Vec(camera.position);
  const glm::dvec3 to_look_at = Vec(camera.look_at) - position_;
  distance_ = glm::length(to_look_at);
  fov_y_degrees_ = camera.fov_y_degrees;
  const glm::dvec3 forward = to_look_at / distance_;
  pitch_ = std::clamp(std::asin(std::clamp(glm::dot(forward, up_), -1.0, 1.0)), -kPitchLimitRadians, kPitchLimitRadians);
  // Yaw is measured from the starting direction's horizontal part, or from
  // any horizontal direction when the camera looks (almost) straight up or down.
  glm::dvec3 horizontal = forward - glm::dot(forward, up_) * up_;
  if (glm::length(horizontal) < 1e-9) {
    horizontal = glm::cross(up_, std::fabs(up_.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0));
  }
  yaw_zero_ = glm::normalize(horizontal);
  yaw_ = 0;
}

glm::dvec3 CameraController::Forward() const {
  // yaw_zero_ x up_ is the camera's right at yaw 0, so a growing yaw turns right.
  const glm::dvec3 right_at_zero = glm::cross(yaw_zero_, up_);
  const glm::dvec3 horizontal = std::cos(yaw_) * yaw_zero_ + std::sin(yaw_) * right_at_zero;
  return std::cos(pitch_) * horizontal + std::sin(pitch_) * up_;
}

glm::dvec3 CameraController::Right() const { return glm::normalize(glm::cross(Forward(), up_)); }

std::array<double, 3> CameraController::pivot() const {
  const glm::dvec3 p = position_ + Forward() * distance_;
  return {p.x, p.y, p.z};
}

void CameraController::Turn(double dx, double dy) {
  const glm::dvec3 pivot = position_ + Forward() * distance_;
  yaw_ = std::remainder(yaw_ + dx * kRadiansPerPixel, 2 * std::numbers::pi);
  pitch_ = std::clamp(pitch_ - dy * kRadiansPerPixel, -kPitchLimitRadians, kPitchLimitRadians);
  // Orbiting turns about the pivot; flying (mouse look) about the camera.
  if (mode_ == CameraMode::kOrbit) position_ = pivot - Forward() * distance_;
}

void CameraController::Update(const CameraInput& input, double viewport_height) {
  if (input.rotate_x != 0 || input.rotate_y != 0) Turn(input.rotate_x, input.rotate_y);

  if (input.pan_x != 0 || input.pan_y != 0) {
    // One pixel at the pivot's distance, so the pivot follows the cursor.
    const double pixel = 2 * distance_ * std::tan(fov_y_degrees_ * std::numbers::pi / 360) / viewport_height;
    const glm::dvec3 right = Right();
    const glm::dvec3 true_up = glm::cross(right, Forward());
    position_ += (-right * input.pan_x + true_up * input.pan_y) * pixel;
  }

  if (input.scroll != 0) {
    if (mode_ == CameraMode::kOrbit) {
      const glm::dvec3 pivot = position_ + Forward() * distance_;
      distance_ = std::clamp(distance_ / std::pow(kZoomPerNotch, input.scroll), kMinDistancePerCube * cube_size_,
                             kMaxDistancePerCube * cube_size_);
      position_ = pivot - Forward() * distance_;
    } else {
      fly_speed_ = std::clamp(fly_speed_ * std::pow(kSpeedPerNotch, input.scroll), kMinSpeedPerCube * cube_size_,
                              kMaxSpeedPerCube * cube_size_);
    }
  }

  if (mode_ == CameraMode::kFly && input.move != std::array<int, 3>{0, 0, 0}) {
    const glm::dvec3 direction = Right() * static_cast<double>(input.move[0]) + up_ * static_cast<double>(input.move[1]) +
                                 Forward() * static_cast<double>(input.move[2]);
    // Normalized, so that moving diagonally is no faster.
    const double speed = fly_speed_ * (input.fast ? kFastFactor : 1);
    position_ += glm::normalize(direction) * speed * input.seconds;
  }
}

Camera CameraController::camera(double aspect) const {
  Camera c;
  c.position = position();
  c.look_at = pivot();
  c.up = {up_.x, up_.y, up_.z};
  c.fov_y_degrees = fov_y_degrees_;
  c.aspect = aspect;
  return c;
}

}  // namespace octocosm
