// Comparing float pictures (the accumulation buffer read back) in tests.
#pragma once

#include <cmath>
#include <cstddef>

#include "render/image.h"

namespace octocosm::testing_support {

// Sum |a - b| / sum |b| over one channel of two pictures of one size.
inline double RelativeL1(const HdrImage& a, const HdrImage& b, int channel = 0) {
  double diff = 0, norm = 0;
  for (std::size_t i = static_cast<std::size_t>(channel); i < a.rgba.size(); i += 4) {
    diff += std::fabs(a.rgba[i] - b.rgba[i]);
    norm += std::fabs(b.rgba[i]);
  }
  return diff / norm;
}

}  // namespace octocosm::testing_support
