// Colour maps for tone mapping: perceptual sequential maps for density
// (magma, inferno, viridis), a diverging one for signed quantities such as
// line-of-sight velocity (coolwarm), and gray. Each is kColorMapKnots RGB
// knots (sRGB values in [0, 1]) interpolated linearly; the GPU gets the same
// knots as uniforms and interpolates them the same way.
#pragma once

#include <array>
#include <string>

namespace octocosm {

enum class ColorMapId { kMagma, kInferno, kViridis, kCoolwarm, kGray };

inline constexpr int kColorMapKnots = 33;

const std::array<std::array<float, 3>, kColorMapKnots>& ColorMapKnots(ColorMapId id);

// The colour at t in [0, 1] (clamped; NaN reads as 0).
std::array<double, 3> SampleColorMap(ColorMapId id, double t);

// "magma", ... <-> ColorMapId. ParseColorMap throws Error::InvalidArgument.
ColorMapId ParseColorMap(const std::string& name);
const char* ColorMapName(ColorMapId id);

}  // namespace octocosm
