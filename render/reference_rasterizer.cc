#include "render/reference_rasterizer.h"

#include <algorithm>
#include <cmath>

#include "base/error.h"
#include "render/splat_kernel.h"

namespace octocosm {

ReferenceRasterizer::ReferenceRasterizer(const RenderView& view) : view_(view) {
  image_.width = view.width();
  image_.height = view.height();
  image_.rgba.assign(4 * static_cast<std::size_t>(view.width()) * view.height(), 0.0);
}

bool ReferenceRasterizer::Add(const double* position, double weight, double smoothing, double attribute,
                              bool selected) {
  ProjectedPoint c;
  if (!view_.Project(position, c)) return false;
  ++points_drawn_;
  const double radius = BlobRadius(smoothing, view_.focal_pixels(), c.depth, view_.max_blob_radius());
  const long i0 = std::max(0L, static_cast<long>(std::ceil(c.x - radius - 0.5)));
  const long i1 = std::min(static_cast<long>(image_.width) - 1, static_cast<long>(std::floor(c.x + radius - 0.5)));
  const long j0 = std::max(0L, static_cast<long>(std::ceil(c.y - radius - 0.5)));
  const long j1 = std::min(static_cast<long>(image_.height) - 1, static_cast<long>(std::floor(c.y + radius - 0.5)));
  if (i0 > i1 || j0 > j1) return true;
  const double amplitude = weight / KernelNormalization(c.x, c.y, radius);
  const double channel[4] = {1, attribute, attribute * attribute, selected ? 1.0 : 0.0};
  for (long j = j0; j <= j1; ++j) {
    const double dy = (static_cast<double>(j) + 0.5 - c.y) / radius;
    double* row = &image_.rgba[4 * static_cast<std::size_t>(j) * static_cast<std::size_t>(image_.width)];
    for (long i = i0; i <= i1; ++i) {
      const double dx = (static_cast<double>(i) + 0.5 - c.x) / radius;
      const double w = CubicKernel(std::sqrt(dx * dx + dy * dy));
      if (w == 0) continue;
      double* px = row + 4 * i;
      for (int k = 0; k < 4; ++k) px[k] += amplitude * w * channel[k];
    }
  }
  return true;
}

void ReferenceRasterizer::Merge(const ReferenceRasterizer& other) {
  if (other.image_.width != image_.width || other.image_.height != image_.height) {
    throw Error::InvalidArgument("ReferenceRasterizer::Merge: images of different sizes");
  }
  for (std::size_t k = 0; k < image_.rgba.size(); ++k) image_.rgba[k] += other.image_.rgba[k];
  points_drawn_ += other.points_drawn_;
}

}  // namespace octocosm
