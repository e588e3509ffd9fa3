// What a rendered image shows: a camera (query/frustum.h) and an image size,
// with the projection both rasterizers use, in double precision.
//
// Eye coordinates of a point p: x = (p - position) . right,
// y = (p - position) . up, depth = (p - position) . forward, with the
// camera's orthonormal basis (Camera::Right, TrueUp, Forward). A point is
// drawn when near <= depth <= far; its centre in window coordinates (pixels,
// origin at the lower-left corner of the image, x right, y up, pixel (i, j)
// centred at (i + 1/2, j + 1/2)) is
//
//     (width / 2 + f x / depth,  height / 2 + f y / depth),   f = height / (2 tan(fov_y / 2)).
//
// The aspect ratio is the image's (width / height): pixels are square.
#pragma once

#include <array>

#include "query/frustum.h"
#include "render/splat_kernel.h"

namespace octocosm {

struct ProjectedPoint {
  double x = 0;      // window coordinates, pixels
  double y = 0;
  double depth = 0;  // along the viewing direction
};

class RenderView {
 public:
  // Throws Error::InvalidArgument for an image size outside 1..16384 pixels,
  // a max blob radius below 1, or a camera Camera::Validate rejects. The
  // camera's aspect is set to width / height.
  RenderView(const Camera& camera, int width, int height, double max_blob_radius = kDefaultMaxBlobRadius);

  const Camera& camera() const { return camera_; }
  int width() const { return width_; }
  int height() const { return height_; }
  double max_blob_radius() const { return max_blob_radius_; }
  double focal_pixels() const { return focal_pixels_; }
  const std::array<double, 3>& right() const { return right_; }
  const std::array<double, 3>& up() const { return up_; }
  const std::array<double, 3>& forward() const { return forward_; }

  // False when the point is not between the near and far planes.
  bool Project(const double* point, ProjectedPoint& out) const;

 private:
  Camera camera_;
  int width_ = 0;
  int height_ = 0;
  double max_blob_radius_ = kDefaultMaxBlobRadius;
  double focal_pixels_ = 0;
  std::array<double, 3> right_{}, up_{}, forward_{};
};

}  // namespace octocosm
