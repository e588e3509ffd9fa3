// PSNR and SSIM on images whose values are known in closed form.
#include <gtest/gtest.h>

#include <random>

#include "base/error.h"
#include "render/image_metrics.h"

namespace octocosm {
namespace {

DisplayImage Constant(float value, int width = 40, int height = 30) {
  return {width, height, std::vector<float>(3 * static_cast<std::size_t>(width) * height, value)};
}

TEST(ImageMetricsTest, IdenticalImagesAreAsGoodAsItGets) {
  DisplayImage noise = Constant(0);
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0, 1);
  for (float& v : noise.rgb) v = u(rng);
  EXPECT_EQ(Psnr(noise, noise), 200);
  EXPECT_NEAR(Ssim(noise, noise), 1, 1e-12);
}

TEST(ImageMetricsTest, AConstantOffsetHasItsClosedFormValues) {
  // PSNR of a uniform error of 0.1: 10 log10(1 / 0.01) = 20 dB. SSIM of two
  // flat images: only the luminance term, (2 x y + C1) / (x^2 + y^2 + C1).
  EXPECT_NEAR(Psnr(Constant(0.5f), Constant(0.6f)), 20, 1e-5);
  const double x = 0.5, y = 0.6, c1 = 1e-4;
  EXPECT_NEAR(Ssim(Constant(0.5f), Constant(0.6f)), (2 * x * y + c1) / (x * x + y * y + c1), 1e-6);
}

TEST(ImageMetricsTest, MoreNoiseIsWorse) {
  DisplayImage base = Constant(0);
  for (std::size_t i = 0; i < base.rgb.size(); ++i) base.rgb[i] = static_cast<float>((i / 3) % 40) / 40.0f;
  std::mt19937 rng(2);
  double last_psnr = 300, last_ssim = 2;
  for (float sigma : {0.01f, 0.05f, 0.2f}) {
    DisplayImage noisy = base;
    std::normal_distribution<float> n(0, sigma);
    for (float& v : noisy.rgb) v += n(rng);
    EXPECT_LT(Psnr(base, noisy), last_psnr);
    EXPECT_LT(Ssim(base, noisy), last_ssim);
    last_psnr = Psnr(base, noisy);
    last_ssim = Ssim(base, noisy);
  }
  EXPECT_THROW(Psnr(Constant(0, 10, 10), Constant(0, 11, 10)), Error);
  EXPECT_THROW(Ssim(Constant(0, 8, 8), Constant(0, 8, 8)), Error);
}

}  // namespace
}  // namespace octocosm
