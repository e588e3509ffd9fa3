#include "index/cluster_shape.h"

#include <algorithm>
#include <cmath>

namespace octocosm {

std::array<std::uint8_t, 6> EncodeShape(const SymmetricMatrix& c) {
  const double mean = (c[0] + c[1] + c[2]) / 3;
  if (!(mean > 0) || !std::isfinite(mean)) return kRoundShapeCode;
  std::array<std::uint8_t, 6> code{};
  for (int i = 0; i < 6; ++i) {
    const double identity = i < 3 ? 1.0 : 0.0;
    // Snapped to 2^-20 before rounding to a code: covariances of points on a
    // lattice (faces, grids) land exactly on a code's rounding boundary, where
    // sums that differ in their last bits (another summation order, float or
    // double input) would otherwise round apart.
    const double s = std::round(((1 - kShapeFloor) * (c[i] / mean) + kShapeFloor * identity) * 0x1p20) * 0x1p-20;
    // NaN entries (never from finite members) fall back to the round value.
    const double q = i < 3 ? std::round(85 * s) : 127 + std::round(254 * s / 3);
    const double round_value = kRoundShapeCode[i];
    code[i] = static_cast<std::uint8_t>(std::clamp(std::isfinite(q) ? q : round_value, 0.0, i < 3 ? 255.0 : 254.0));
  }
  return code;
}

SymmetricMatrix DecodeShape(const std::array<std::uint8_t, 6>& code) {
  SymmetricMatrix s{};
  for (int i = 0; i < 3; ++i) s[i] = code[i] / 85.0;
  for (int i = 3; i < 6; ++i) s[i] = (code[i] - 127) * 3.0 / 254.0;
  return s;
}

}  // namespace octocosm
