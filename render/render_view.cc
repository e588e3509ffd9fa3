#include "render/render_view.h"

#include <cmath>
#include <numbers>
#include <string>

#include "base/error.h"

namespace octocosm {

RenderView::RenderView(const Camera& camera, int width, int height, double max_blob_radius)
    : camera_(camera), width_(width), height_(height), max_blob_radius_(max_blob_radius) {
  constexpr int kMaxImageSide = 16384;
  if (width < 1 || height < 1 || width > kMaxImageSide || height > kMaxImageSide) {
    throw Error::InvalidArgument("image size " + std::to_string(width) + "x" + std::to_string(height) +
                                 " is outside 1..16384 pixels per side");
  }
  if (!(max_blob_radius >= kMinBlobRadius) || !std::isfinite(max_blob_radius)) {
    throw Error::InvalidArgument("the largest blob radius must be at least 1 pixel");
  }
  camera_.aspect = static_cast<double>(width) / height;
  camera_.Validate();
  focal_pixels_ = height / (2 * std::tan(camera_.fov_y_degrees * std::numbers::pi / 360));
  right_ = camera_.Right();
  up_ = camera_.TrueUp();
  forward_ = camera_.Forward();
}

bool RenderView::Project(const double* point, ProjectedPoint& out) const {
  const double d[3] = {point[0] - camera_.position[0], point[1] - camera_.position[1], point[2] - camera_.position[2]};
  const double depth = d[0] * forward_[0] + d[1] * forward_[1] + d[2] * forward_[2];
  if (!(depth >= camera_.near && depth <= camera_.far)) return false;
  const double x = d[0] * right_[0] + d[1] * right_[1] + d[2] * right_[2];
  const double y = d[0] * up_[0] + d[1] * up_[1] + d[2] * up_[2];
  out.x = width_ / 2.0 + focal_pixels_ * x / depth;
  out.y = height_ / 2.0 + focal_pixels_ * y / depth;
  out.depth = depth;
  return true;
}

}  // namespace octocosm
