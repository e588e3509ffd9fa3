#include "render/image_metrics.h"

#include <cmath>
#include <vector>

#include "base/error.h"

namespace octocosm {
namespace {

void CheckSameSize(const DisplayImage& a, const DisplayImage& b) {
  if (a.width != b.width || a.height != b.height || a.rgb.size() != b.rgb.size()) {
    throw Error::InvalidArgument("comparing images of different sizes (" + std::to_string(a.width) + "x" +
                                 std::to_string(a.height) + " and " + std::to_string(b.width) + "x" +
                                 std::to_string(b.height) + ")");
  }
}

std::vector<double> Luminance(const DisplayImage& image) {
  std::vector<double> y(static_cast<std::size_t>(image.width) * image.height);
  for (std::size_t p = 0; p < y.size(); ++p) {
    y[p] = 0.2126 * image.rgb[3 * p] + 0.7152 * image.rgb[3 * p + 1] + 0.0722 * image.rgb[3 * p + 2];
  }
  return y;
}

// The separable Gaussian window, applied along rows then columns; only the
// "valid" region (windows inside the image) is kept.
std::vector<double> Filter(const std::vector<double>& in, int width, int height, const std::vector<double>& kernel) {
  const int r = static_cast<int>(kernel.size() / 2);
  const int w = width - 2 * r, h = height - 2 * r;
  std::vector<double> rows(static_cast<std::size_t>(w) * height), out(static_cast<std::size_t>(w) * h);
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < w; ++i) {
      double s = 0;
      for (int k = 0; k <= 2 * r; ++k) s += kernel[static_cast<std::size_t>(k)] * in[static_cast<std::size_t>(j) * width + i + k];
      rows[static_cast<std::size_t>(j) * w + i] = s;
    }
  }
  for (int j = 0; j < h; ++j) {
    for (int i = 0; i < w; ++i) {
      double s = 0;
      for (int k = 0; k <= 2 * r; ++k) s += kernel[static_cast<std::size_t>(k)] * rows[static_cast<std::size_t>(j + k) * w + i];
      out[static_cast<std::size_t>(j) * w + i] = s;
    }
  }
  return out;
}

}  // namespace

double Psnr(const DisplayImage& a, const DisplayImage& b) {
  CheckSameSize(a, b);
  double squared = 0;
  for (std::size_t i = 0; i < a.rgb.size(); ++i) {
    const double d = static_cast<double>(a.rgb[i]) - b.rgb[i];
    squared += d * d;
  }
  if (a.rgb.empty() || squared == 0) return 200;
  return 10 * std::log10(static_cast<double>(a.rgb.size()) / squared);
}

double Ssim(const DisplayImage& a, const DisplayImage& b) {
  CheckSameSize(a, b);
  constexpr int kRadius = 5;
  constexpr double kSigma = 1.5, kC1 = 0.01 * 0.01, kC2 = 0.03 * 0.03;
  if (a.width <= 2 * kRadius || a.height <= 2 * kRadius) {
    throw Error::InvalidArgument("SSIM needs images larger than its 11x11 window");
  }
  std::vector<double> kernel(2 * kRadius + 1);
  double total = 0;
  for (int k = -kRadius; k <= kRadius; ++k) total += kernel[static_cast<std::size_t>(k + kRadius)] = std::exp(-k * k / (2 * kSigma * kSigma));
  for (double& k : kernel) k /= total;
  const std::vector<double> x = Luminance(a), y = Luminance(b);
  std::vector<double> xx(x.size()), yy(x.size()), xy(x.size());
  for (std::size_t p = 0; p < x.size(); ++p) {
    xx[p] = x[p] * x[p];
    yy[p] = y[p] * y[p];
    xy[p] = x[p] * y[p];
  }
  const auto mx = Filter(x, a.width, a.height, kernel), my = Filter(y, a.width, a.height, kernel);
  const auto sxx = Filter(xx, a.width, a.height, kernel), syy = Filter(yy, a.width, a.height, kernel);
  const auto sxy = Filter(xy, a.width, a.height, kernel);
  double sum = 0;
  for (std::size_t p = 0; p < mx.size(); ++p) {
    const double vx = sxx[p] - mx[p] * mx[p], vy = syy[p] - my[p] * my[p], cxy = sxy[p] - mx[p] * my[p];
    sum += ((2 * mx[p] * my[p] + kC1) * (2 * cxy + kC2)) / ((mx[p] * mx[p] + my[p] * my[p] + kC1) * (vx + vy + kC2));
  }
  return sum / static_cast<double>(mx.size());
}

}  // namespace octocosm
