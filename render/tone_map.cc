#include "render/tone_map.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "base/error.h"

namespace octocosm {

ColorMode ParseColorMode(const std::string& name) {
  if (name == "density") return ColorMode::kDensity;
  if (name == "speed") return ColorMode::kSpeed;
  if (name == "los-velocity") return ColorMode::kLineOfSightVelocity;
  if (name == "dispersion") return ColorMode::kVelocityDispersion;
  if (name == "type") return ColorMode::kType;
  throw Error::InvalidArgument("unknown colour mode '" + name +
                               "': expected density, speed, los-velocity, dispersion or type");
}

ColorMapId DefaultAttributeColorMap(ColorMode mode) {
  return mode == ColorMode::kLineOfSightVelocity ? ColorMapId::kCoolwarm : ColorMapId::kViridis;
}

const char* ColorModeName(ColorMode mode) {
  switch (mode) {
    case ColorMode::kDensity: return "density";
    case ColorMode::kSpeed: return "speed";
    case ColorMode::kLineOfSightVelocity: return "los-velocity";
    case ColorMode::kVelocityDispersion: return "dispersion";
    case ColorMode::kType: return "type";
  }
  return "density";
}

ToneCurve ParseToneCurve(const std::string& name) {
  if (name == "log") return ToneCurve::kLog;
  if (name == "asinh") return ToneCurve::kAsinh;
  throw Error::InvalidArgument("unknown tone curve '" + name + "': expected log or asinh");
}

const char* ToneCurveName(ToneCurve curve) { return curve == ToneCurve::kAsinh ? "asinh" : "log"; }

bool ColorModeNeedsVelocity(ColorMode mode) {
  return mode == ColorMode::kSpeed || mode == ColorMode::kLineOfSightVelocity || mode == ColorMode::kVelocityDispersion;
}

double PointAttribute(ColorMode mode, const float* velocity, std::uint8_t type, const RenderView& view) {
  switch (mode) {
    case ColorMode::kDensity: return 0;
    case ColorMode::kSpeed:
      return std::sqrt(double{velocity[0]} * velocity[0] + double{velocity[1]} * velocity[1] +
                       double{velocity[2]} * velocity[2]);
    case ColorMode::kLineOfSightVelocity:
    case ColorMode::kVelocityDispersion: {
      const auto& f = view.forward();
      return velocity[0] * f[0] + velocity[1] * f[1] + velocity[2] * f[2];
    }
    case ColorMode::kType: return type;
  }
  return 0;
}

void ToneMapSettings::Validate() const {
  if (!(exposure >= 0) || !std::isfinite(exposure)) throw Error::InvalidArgument("exposure must be >= 0 (0: automatic)");
  if (!(auto_percentile > 0 && auto_percentile <= 100)) {
    throw Error::InvalidArgument("the automatic exposure's percentile must be in (0, 100]");
  }
  if (!(log_decades > 0 && log_decades <= 30)) throw Error::InvalidArgument("the log curve's range must be 0 to 30 decades");
  if (!(asinh_softening > 0 && asinh_softening < 1)) throw Error::InvalidArgument("the asinh softening must be in (0, 1)");
  if (!std::isfinite(attribute_low) || !std::isfinite(attribute_high) || attribute_low > attribute_high) {
    throw Error::InvalidArgument("the colour range must be two finite numbers, low <= high");
  }
}

double PixelAttribute(ColorMode mode, double d, double a_sum, double a2_sum) {
  if (mode == ColorMode::kDensity || !(d > 0)) return 0;
  const double mean = a_sum / d;
  if (mode != ColorMode::kVelocityDispersion) return mean;
  return std::sqrt(std::max(a2_sum / d - mean * mean, 0.0));
}

namespace {

int Bin(double fraction) {
  return static_cast<int>(std::clamp(std::floor(fraction * kHistogramBins), 0.0, kHistogramBins - 1.0));
}

double Brightness(ToneCurve curve, double d, double exposure, double floor) {
  if (!(d > 0)) return 0;
  const double b = curve == ToneCurve::kLog ? std::log(d / floor) / std::log(exposure / floor)
                                            : std::asinh(d / floor) / std::asinh(exposure / floor);
  return std::clamp(b, 0.0, 1.0);
}

}  // namespace

ImageStatistics MeasureImage(const HdrImage& image, ColorMode mode) {
  ImageStatistics s;
  const std::size_t pixels = static_cast<std::size_t>(image.width) * image.height;
  const bool attribute = mode != ColorMode::kDensity;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (std::size_t p = 0; p < pixels; ++p) {
    const double* px = &image.rgba[4 * p];
    if (!(px[0] > 0)) continue;
    s.max_density = std::max(s.max_density, px[0]);
    if (attribute) {
      const double x = PixelAttribute(mode, px[0], px[1], px[2]);
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
  }
  if (!(s.max_density > 0)) return s;
  if (attribute) {
    s.attribute_min = lo;
    s.attribute_max = hi;
  }
  const double attribute_span = s.attribute_max - s.attribute_min;
  for (std::size_t p = 0; p < pixels; ++p) {
    const double* px = &image.rgba[4 * p];
    if (!(px[0] > 0)) continue;
    ++s.density[static_cast<std::size_t>(
        Bin((std::log2(px[0] / s.max_density) + kDensityHistogramOctaves) / kDensityHistogramOctaves))];
    if (attribute && px[0] >= s.max_density * kAttributeDensityFloor) {
      const double x = PixelAttribute(mode, px[0], px[1], px[2]);
      ++s.attribute[static_cast<std::size_t>(attribute_span > 0 ? Bin((x - s.attribute_min) / attribute_span) : 0)];
    }
  }
  return s;
}

double HistogramPercentile(const std::array<std::uint32_t, kHistogramBins>& histogram, double lo, double hi,
                           double percentile) {
  std::uint64_t total = 0;
  for (std::uint32_t c : histogram) total += c;
  if (total == 0) return lo;
  const double target = std::clamp(percentile, 0.0, 100.0) / 100 * static_cast<double>(total);
  double below = 0;
  for (int k = 0; k < kHistogramBins; ++k) {
    const double count = histogram[static_cast<std::size_t>(k)];
    if (count > 0 && below + count >= target) {
      const double fraction = std::clamp((target - below) / count, 0.0, 1.0);
      return lo + (k + fraction) * (hi - lo) / kHistogramBins;
    }
    below += count;
  }
  return hi;
}

double AutomaticExposure(const ToneMapSettings& settings, const ImageStatistics& statistics) {
  if (settings.exposure > 0) return settings.exposure;
  if (!(statistics.max_density > 0)) return 1;  // an empty picture: any exposure shows it black
  const double octaves =
      HistogramPercentile(statistics.density, -kDensityHistogramOctaves, 0, settings.auto_percentile);
  return statistics.max_density * std::exp2(octaves);
}

ToneMapParameters ResolveToneMap(const ToneMapSettings& settings, const ImageStatistics& statistics, double exposure) {
  settings.Validate();
  ToneMapParameters p;
  p.curve = settings.curve;
  p.exposure = exposure > 0 ? exposure : AutomaticExposure(settings, statistics);
  p.floor = p.exposure * (settings.curve == ToneCurve::kLog ? std::pow(10.0, -settings.log_decades) : settings.asinh_softening);
  p.density_map = settings.density_map;
  p.color = settings.color;
  p.attribute_map = settings.attribute_map;
  p.highlight = settings.highlight;
  if (settings.attribute_low < settings.attribute_high) {
    p.attribute_low = settings.attribute_low;
    p.attribute_high = settings.attribute_high;
  } else if (settings.color != ColorMode::kDensity) {
    p.attribute_low = HistogramPercentile(statistics.attribute, statistics.attribute_min, statistics.attribute_max, 1);
    p.attribute_high = HistogramPercentile(statistics.attribute, statistics.attribute_min, statistics.attribute_max, 99);
    if (settings.color == ColorMode::kLineOfSightVelocity) {
      const double m = std::max(std::fabs(p.attribute_low), std::fabs(p.attribute_high));
      p.attribute_low = -m;
      p.attribute_high = m;
    }
    // A range within float rounding of its values is one value (every
    // particle of one type, say, whose per-pixel mean the GPU's sums give as
    // 1 +- 1e-7): spread over the colour map it would only show rounding.
    const double magnitude = std::max(std::fabs(p.attribute_low), std::fabs(p.attribute_high));
    if (!(p.attribute_high - p.attribute_low > 1e-5 * magnitude)) p.attribute_high = p.attribute_low + std::max(1.0, magnitude);
  }
  return p;
}

std::array<double, 3> ToneMapPixel(const ToneMapParameters& p, const double* rgba) {
  const double b = Brightness(p.curve, rgba[0], p.exposure, p.floor);
  std::array<double, 3> rgb;
  if (p.color == ColorMode::kDensity) {
    rgb = SampleColorMap(p.density_map, b);
  } else {
    const double x = PixelAttribute(p.color, rgba[0], rgba[1], rgba[2]);
    rgb = SampleColorMap(p.attribute_map, (x - p.attribute_low) / (p.attribute_high - p.attribute_low));
    for (double& c : rgb) c *= b;
  }
  const double h = Brightness(p.curve, rgba[3], p.exposure, p.floor);
  for (int c = 0; c < 3; ++c) rgb[static_cast<std::size_t>(c)] = rgb[static_cast<std::size_t>(c)] * (1 - h) + p.highlight[static_cast<std::size_t>(c)] * h;
  return rgb;
}

DisplayImage ToneMap(const HdrImage& image, const ToneMapParameters& parameters) {
  DisplayImage out{image.width, image.height, {}};
  const std::size_t pixels = static_cast<std::size_t>(image.width) * image.height;
  out.rgb.resize(3 * pixels);
  for (std::size_t p = 0; p < pixels; ++p) {
    const auto rgb = ToneMapPixel(parameters, &image.rgba[4 * p]);
    for (int c = 0; c < 3; ++c) out.rgb[3 * p + static_cast<std::size_t>(c)] = static_cast<float>(rgb[static_cast<std::size_t>(c)]);
  }
  return out;
}

RgbImage ToBytes(const DisplayImage& image) {
  RgbImage out{image.width, image.height, std::vector<std::uint8_t>(image.rgb.size())};
  for (std::size_t i = 0; i < image.rgb.size(); ++i) {
    out.rgb[i] = static_cast<std::uint8_t>(std::lround(std::clamp(image.rgb[i], 0.0f, 1.0f) * 255.0f));
  }
  return out;
}

double ExposureSmoother::Update(double target_exposure, double elapsed_seconds) {
  if (!(target_exposure > 0) || !std::isfinite(target_exposure)) return current_;
  if (!(current_ > 0) || !(time_constant_ > 0)) {
    current_ = target_exposure;
    return current_;
  }
  const double k = 1 - std::exp(-std::max(elapsed_seconds, 0.0) / time_constant_);
  current_ = std::exp(std::log(current_) + (std::log(target_exposure) - std::log(current_)) * k);
  return current_;
}

}  // namespace octocosm
