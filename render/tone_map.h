// From accumulated mass to a picture: colour modes, automatic exposure, tone
// curves and colour maps. The CPU functions here are the specification; the
// GPU's shaders/tone_map.frag.glsl and shaders/image_stats.comp.glsl do the
// same arithmetic (tests compare them).
//
// Colour modes. Each point may carry an attribute a, accumulated mass-weighted
// (render/image.h): per pixel, the mass-weighted mean <a> = G / R and the
// dispersion sqrt(<a^2> - <a>^2) = sqrt(B / R - (G / R)^2).
//   density       no attribute: colour = colour map(brightness)
//   speed         mean |v|
//   los-velocity  mean line-of-sight velocity v . forward (positive: receding)
//   dispersion    dispersion of the line-of-sight velocity
//   type          mean particle type
// With an attribute, colour = attribute map((x - lo) / (hi - lo)) * brightness.
//
// Brightness from the density D (mass per pixel) and the exposure E (the
// density shown at full brightness):
//   log    b = clamp(log(D / L) / log(E / L), 0, 1),  L = E * 10^-decades
//   asinh  b = clamp(asinh(D / S) / asinh(E / S), 0, 1),  S = E * softening
// Selected particles (channel A, their own density) are painted over in the
// highlight colour with their own brightness h: colour = colour (1 - h) +
// highlight * h.
//
// Automatic settings come from two passes over the image (ImageStatistics):
// the maximum density Dmax (and the attribute's range over lit pixels), then
// a histogram of log2(D / Dmax) over the 32 octaves below Dmax in 1/32-octave
// bins, and a histogram of the attribute over pixels with D >= Dmax / 1024.
// The exposure is the auto_percentile-th percentile of the density histogram
// (default 99.5: a few bright pixels may saturate), the attribute range its
// 1st to 99th percentile (symmetric about 0 for the line-of-sight velocity).
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "render/color_maps.h"
#include "render/image.h"
#include "render/render_view.h"

namespace octocosm {

enum class ColorMode { kDensity, kSpeed, kLineOfSightVelocity, kVelocityDispersion, kType };
enum class ToneCurve { kLog, kAsinh };

ColorMode ParseColorMode(const std::string& name);  // density, speed, los-velocity, dispersion, type
const char* ColorModeName(ColorMode mode);
ToneCurve ParseToneCurve(const std::string& name);  // log, asinh
const char* ToneCurveName(ToneCurve curve);

// Whether the mode needs the points' velocities.
bool ColorModeNeedsVelocity(ColorMode mode);

// The attribute a of one point (0 for density).
double PointAttribute(ColorMode mode, const float* velocity, std::uint8_t type, const RenderView& view);

// The attribute colour map when none is given: coolwarm for the
// line-of-sight velocity (signed, about 0), viridis otherwise.
ColorMapId DefaultAttributeColorMap(ColorMode mode);

struct ToneMapSettings {
  ToneCurve curve = ToneCurve::kLog;
  double exposure = 0;            // density at full brightness; 0: automatic
  double auto_percentile = 99.5;  // percentile of lit pixels' density used as the automatic exposure
  double log_decades = 4;         // log curve: decades of density below the exposure that are visible
  double asinh_softening = 1e-3;  // asinh curve: linear below exposure * softening
  ColorMapId density_map = ColorMapId::kMagma;
  ColorMode color = ColorMode::kDensity;
  ColorMapId attribute_map = ColorMapId::kViridis;
  double attribute_low = 0, attribute_high = 0;  // equal: automatic
  std::array<double, 3> highlight{0.35, 1.0, 0.35};

  // Throws Error::InvalidArgument for values out of range.
  void Validate() const;
};

inline constexpr int kHistogramBins = 1024;
inline constexpr int kDensityHistogramOctaves = 32;
inline constexpr double kAttributeDensityFloor = 1.0 / 1024;  // of Dmax: pixels that count for the attribute range

struct ImageStatistics {
  double max_density = 0;
  double attribute_min = 0, attribute_max = 0;  // over pixels with D > 0
  std::array<std::uint32_t, kHistogramBins> density{};    // log2(D / Dmax) in [-32, 0)
  std::array<std::uint32_t, kHistogramBins> attribute{};  // [min, max] over pixels with D >= Dmax * floor
};

// The tone mapping with every automatic value made concrete: what the shader
// receives.
struct ToneMapParameters {
  ToneCurve curve = ToneCurve::kLog;
  double exposure = 1;
  double floor = 1e-4;  // L of the log curve, S of the asinh curve
  ColorMapId density_map = ColorMapId::kMagma;
  ColorMode color = ColorMode::kDensity;
  ColorMapId attribute_map = ColorMapId::kViridis;
  double attribute_low = 0, attribute_high = 1;
  std::array<double, 3> highlight{0.35, 1.0, 0.35};
};

// The pixel's colour value x (mean or dispersion) from its accumulated
// channels; 0 for density or an empty pixel.
double PixelAttribute(ColorMode mode, double d, double a_sum, double a2_sum);

ImageStatistics MeasureImage(const HdrImage& image, ColorMode mode);

// The value at `percentile` (0..100) of a histogram whose bins cover [lo, hi)
// evenly, interpolated inside the bin; lo when the histogram is empty.
double HistogramPercentile(const std::array<std::uint32_t, kHistogramBins>& histogram, double lo, double hi,
                           double percentile);

// The automatic exposure alone (settings.exposure when it is set).
double AutomaticExposure(const ToneMapSettings& settings, const ImageStatistics& statistics);

// Resolves the automatic values of `settings` from `statistics`; `exposure`
// overrides the exposure (for a smoothed one, see ExposureSmoother) when > 0.
ToneMapParameters ResolveToneMap(const ToneMapSettings& settings, const ImageStatistics& statistics,
                                 double exposure = 0);

// The colour of one pixel from its four channels.
std::array<double, 3> ToneMapPixel(const ToneMapParameters& p, const double* rgba);

DisplayImage ToneMap(const HdrImage& image, const ToneMapParameters& parameters);

// Rounds to 8 bits as GL does when it stores a float in an RGBA8 target.
RgbImage ToBytes(const DisplayImage& image);

// Keeps the exposure steady over a sequence of frames (playback, camera
// paths): moves towards each frame's automatic exposure in log space with a
// time constant, so a few bright pixels entering the view do not make the
// picture flicker. The first update takes the target as it is.
class ExposureSmoother {
 public:
  explicit ExposureSmoother(double time_constant_seconds = 0.5) : time_constant_(time_constant_seconds) {}
  double Update(double target_exposure, double elapsed_seconds);
  double current() const { return current_; }
  void Reset() { current_ = 0; }

 private:
  double time_constant_;
  double current_ = 0;
};

}  // namespace octocosm
