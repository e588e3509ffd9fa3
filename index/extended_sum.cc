#include "index/extended_sum.h"

namespace octocosm {

long double ExtendedSum(std::span<const double> values) {
  long double sum = 0;
  for (const double v : values) sum += v;
  return sum;
}

}  // namespace octocosm
