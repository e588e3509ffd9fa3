#include "render/splat_kernel.h"

#include <algorithm>
#include <cmath>

namespace octocosm {

double CubicKernel(double q) {
  if (!(q < 1)) return 0;
  if (q < 0.5) return 1 - 6 * q * q + 6 * q * q * q;
  const double r = 1 - q;
  return 2 * r * r * r;
}

double BlobRadius(double smoothing, double focal_pixels, double depth, double max_radius) {
  return std::clamp(smoothing * focal_pixels / depth, kMinBlobRadius, max_radius);
}

double KernelPixelSum(double cx, double cy, double radius) {
  // Pixel centres within the disc: i + 1/2 in (cx - R, cx + R).
  const long i0 = static_cast<long>(std::ceil(cx - radius - 0.5));
  const long i1 = static_cast<long>(std::floor(cx + radius - 0.5));
  const long j0 = static_cast<long>(std::ceil(cy - radius - 0.5));
  const long j1 = static_cast<long>(std::floor(cy + radius - 0.5));
  double sum = 0;
  for (long j = j0; j <= j1; ++j) {
    const double dy = (static_cast<double>(j) + 0.5 - cy) / radius;
    for (long i = i0; i <= i1; ++i) {
      const double dx = (static_cast<double>(i) + 0.5 - cx) / radius;
      sum += CubicKernel(std::sqrt(dx * dx + dy * dy));
    }
  }
  return sum;
}

double KernelNormalization(double cx, double cy, double radius) {
  if (radius < kExactNormalizationRadius) return KernelPixelSum(cx, cy, radius);
  return kKernelIntegral * radius * radius;
}

int GuardMargin(double max_radius) { return static_cast<int>(std::ceil(max_radius)) + 1; }

double SpriteSize(double radius) { return 2 * radius + kSpriteGuard; }

}  // namespace octocosm
