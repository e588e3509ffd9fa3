// The reference rasterizer: blobs accumulated on the CPU in double precision,
// with exactly the kernel of render/splat_kernel.h and the projection of
// render/render_view.h. `octocosm render --reference` feeds it every particle
// of the original snapshots: the picture every level-of-detail rendering is
// judged against. It draws on the whole plane and keeps the image's pixels,
// so a blob centred outside the image still adds what reaches in.
//
// Not thread-safe; to use several threads give each its own rasterizer and
// Merge them (sums are then in a different order: the result agrees to
// rounding, not bit for bit).
#pragma once

#include <cstdint>

#include "render/image.h"
#include "render/render_view.h"

namespace octocosm {

class ReferenceRasterizer {
 public:
  explicit ReferenceRasterizer(const RenderView& view);

  // Adds one point: absolute position, weight (mass), smoothing length,
  // colour attribute (render/tone_map.h PointAttribute) and whether its ID is
  // selected. Returns false when the point is not drawn (outside the near/far
  // range); a point whose blob misses the image is drawn (counted) but adds
  // nothing.
  bool Add(const double* position, double weight, double smoothing, double attribute, bool selected);

  // Adds the other rasterizer's sums (same view) to this one.
  void Merge(const ReferenceRasterizer& other);

  const HdrImage& image() const { return image_; }
  std::uint64_t points_drawn() const { return points_drawn_; }

 private:
  RenderView view_;
  HdrImage image_;
  std::uint64_t points_drawn_ = 0;
};

}  // namespace octocosm
