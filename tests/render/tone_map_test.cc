// Tone mapping on the CPU: the specification the GPU's shaders follow.
#include <gtest/gtest.h>

#include <cmath>

#include "base/error.h"
#include "render/tone_map.h"

namespace octocosm {
namespace {

HdrImage Ramp(int width, int height) {
  HdrImage image{width, height, std::vector<double>(4 * static_cast<std::size_t>(width) * height, 0.0)};
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < width; ++i) {
      double* px = &image.rgba[4 * (static_cast<std::size_t>(j) * width + i)];
      px[0] = std::pow(10.0, -6 + 6.0 * i / (width - 1));  // 1e-6 .. 1
      px[1] = px[0] * (j - height / 2.0);                  // attribute j - h/2
      px[2] = px[0] * (j - height / 2.0) * (j - height / 2.0);
    }
  }
  return image;
}

TEST(ToneMapTest, PercentileOfAHistogramInterpolatesInsideItsBin) {
  std::array<std::uint32_t, kHistogramBins> h{};
  h[10] = 100;
  EXPECT_DOUBLE_EQ(HistogramPercentile(h, 0, kHistogramBins, 50), 10.5);
  EXPECT_DOUBLE_EQ(HistogramPercentile(h, 0, kHistogramBins, 100), 11);
  std::array<std::uint32_t, kHistogramBins> empty{};
  EXPECT_DOUBLE_EQ(HistogramPercentile(empty, -3, 5, 50), -3);
}

TEST(ToneMapTest, AutomaticExposureIsThePercentileOfTheLitPixels) {
  const HdrImage image = Ramp(1000, 4);
  const ImageStatistics s = MeasureImage(image, ColorMode::kDensity);
  EXPECT_DOUBLE_EQ(s.max_density, 1);
  ToneMapSettings settings;
  settings.auto_percentile = 50;
  // Half the pixels lie below 1e-3 on a log ramp from 1e-6 to 1; one bin is 1/32 octave.
  EXPECT_NEAR(std::log2(AutomaticExposure(settings, s)), std::log2(1e-3), 1.0 / 32);
  settings.exposure = 0.25;
  EXPECT_DOUBLE_EQ(AutomaticExposure(settings, s), 0.25);
}

TEST(ToneMapTest, BrightnessGrowsWithDensityAndSaturatesAtTheExposure) {
  ToneMapParameters p;
  p.exposure = 1;
  p.floor = 1e-4;
  p.density_map = ColorMapId::kGray;
  double last = -1;
  for (double d = 1e-5; d < 10; d *= 1.5) {
    const double rgba[4] = {d, 0, 0, 0};
    const double v = ToneMapPixel(p, rgba)[0];
    EXPECT_GE(v, last);
    last = v;
  }
  const double at_exposure[4] = {1, 0, 0, 0}, at_floor[4] = {1e-4, 0, 0, 0};
  EXPECT_NEAR(ToneMapPixel(p, at_exposure)[0], 1, 1e-12);
  EXPECT_NEAR(ToneMapPixel(p, at_floor)[0], 0, 1e-12);
  p.curve = ToneCurve::kAsinh;
  EXPECT_NEAR(ToneMapPixel(p, at_exposure)[0], 1, 1e-12);
}

TEST(ToneMapTest, DispersionAndMeanComeFromTheAccumulatedMoments) {
  // Two blobs' shares in one pixel: mass 1 with a = 3 and mass 3 with a = -1.
  const double d = 4, a = 1 * 3 + 3 * -1, a2 = 1 * 9 + 3 * 1;
  EXPECT_DOUBLE_EQ(PixelAttribute(ColorMode::kSpeed, d, a, a2), 0);
  EXPECT_DOUBLE_EQ(PixelAttribute(ColorMode::kVelocityDispersion, d, a, a2), std::sqrt(3.0));
  EXPECT_DOUBLE_EQ(PixelAttribute(ColorMode::kDensity, d, a, a2), 0);
}

TEST(ToneMapTest, AutomaticAttributeRangeIsSymmetricForLineOfSightVelocity) {
  const HdrImage image = Ramp(64, 100);
  ToneMapSettings settings;
  settings.color = ColorMode::kLineOfSightVelocity;
  const ToneMapParameters p = ResolveToneMap(settings, MeasureImage(image, settings.color));
  EXPECT_DOUBLE_EQ(p.attribute_low, -p.attribute_high);
  EXPECT_NEAR(p.attribute_high, 49, 2);
  settings.color = ColorMode::kSpeed;
  const ToneMapParameters q = ResolveToneMap(settings, MeasureImage(image, settings.color));
  EXPECT_NEAR(q.attribute_low, -49, 2);
  EXPECT_LT(q.attribute_low, q.attribute_high);
}

// Every pixel's attribute 1 to float rounding (one particle type, summed by
// float atomics in no fixed order): the automatic range is not stretched over
// the rounding, so every pixel gets the same colour.
TEST(ToneMapTest, AnAttributeRangeWithinRoundingIsOneValue) {
  HdrImage image{64, 1, std::vector<double>(4 * 64)};
  for (std::size_t x = 0; x < 64; ++x) {
    const double mass = 1.0 + static_cast<double>(x), mean = x % 2 == 0 ? 1.0 : 1.0 + 1.2e-7;
    image.rgba[4 * x] = mass;
    image.rgba[4 * x + 1] = mass * mean;
    image.rgba[4 * x + 2] = mass * mean * mean;
  }
  ToneMapSettings settings;
  settings.color = ColorMode::kType;
  const ToneMapParameters p = ResolveToneMap(settings, MeasureImage(image, settings.color));
  EXPECT_GE(p.attribute_high - p.attribute_low, 1);
  // The colour's share of green, whatever the brightness.
  auto green = [&](std::size_t x) {
    const std::array<double, 3> rgb = ToneMapPixel(p, &image.rgba[4 * x]);
    return rgb[1] / (rgb[0] + rgb[1] + rgb[2]);
  };
  for (std::size_t x = 1; x < 64; ++x) EXPECT_NEAR(green(x), green(0), 1e-5) << x;
}

TEST(ToneMapTest, SelectedMassIsPaintedInTheHighlightColour) {
  ToneMapParameters p;
  p.exposure = 1;
  p.floor = 1e-4;
  const double selected[4] = {1, 0, 0, 1}, plain[4] = {1, 0, 0, 0};
  const auto s = ToneMapPixel(p, selected), n = ToneMapPixel(p, plain);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(s[c], p.highlight[c], 1e-12);
  EXPECT_NE(n[1], s[1]);
}

TEST(ToneMapTest, ExposureSmootherApproachesTheTargetWithItsTimeConstant) {
  ExposureSmoother smoother(0.5);
  EXPECT_DOUBLE_EQ(smoother.Update(1, 0.1), 1);  // the first frame takes the target
  // One time constant later the log distance has shrunk by 1/e.
  const double after = smoother.Update(std::exp(1.0), 0.5);
  EXPECT_NEAR(std::log(after), 1 - std::exp(-1.0), 1e-12);
  EXPECT_DOUBLE_EQ(smoother.Update(0, 0.1), after);  // an empty frame keeps the exposure
}

TEST(ToneMapTest, SettingsOutOfRangeAreRejected) {
  ToneMapSettings s;
  s.log_decades = 0;
  EXPECT_THROW(s.Validate(), Error);
  s = {};
  s.attribute_low = 2;
  s.attribute_high = 1;
  EXPECT_THROW(s.Validate(), Error);
  EXPECT_THROW(ParseColorMode("rainbow"), Error);
  EXPECT_EQ(ParseColorMode("dispersion"), ColorMode::kVelocityDispersion);
}

TEST(ToneMapTest, BytesRoundAsGlDoes) {
  DisplayImage d{2, 1, {0.0f, 1.0f, 0.5f, 2.0f, -1.0f, 127.5f / 255}};
  const RgbImage b = ToBytes(d);
  EXPECT_EQ(b.rgb, (std::vector<std::uint8_t>{0, 255, 128, 255, 0, 128}));
}

}  // namespace
}  // namespace octocosm
