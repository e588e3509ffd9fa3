#include "index/nth_largest.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>

namespace octocosm {
namespace {

// Selects rank k under `order` (std::greater: from the largest; std::less:
// from the smallest) through a bound read off the sample, as the header says.
template <typename Order>
double Select(std::span<const double> values, std::size_t k, Order order) {
  const std::size_t m = values.size();
  constexpr std::size_t kSampleSize = 1024;
  // Not value-initialised: every entry used is written first.
  const std::unique_ptr<double[]> candidates = std::make_unique_for_overwrite<double[]>(m);
  std::size_t count = 0;
  if (m >= 8 * kSampleSize) {
    double sample[kSampleSize];
    for (std::size_t j = 0; j < kSampleSize; ++j) sample[j] = values[j * m / kSampleSize];
    const double expected = static_cast<double>(k + 1) * kSampleSize / static_cast<double>(m);
    const std::size_t sample_rank =
        std::min(kSampleSize - 1, static_cast<std::size_t>(expected + 4 * std::sqrt(expected) + 16));
    std::nth_element(sample, sample + sample_rank, sample + kSampleSize, order);
    const double bound = sample[sample_rank];
    for (const double v : values) {
      candidates[count] = v;
      count += order(bound, v) ? 0 : 1;  // v at or before the bound
    }
  }
  if (count <= k) {
    std::copy(values.begin(), values.end(), candidates.get());
    count = m;
  }
  std::nth_element(candidates.get(), candidates.get() + k, candidates.get() + count, order);
  return candidates[k];
}

}  // namespace

double NthLargest(std::span<const double> values, std::size_t rank) {
  // Counted from the nearer end, so that at most about half the values are
  // candidates.
  const std::size_t m = values.size();
  if (rank < m / 2) return Select(values, rank, std::greater<>());
  return Select(values, m - 1 - rank, std::less<>());
}

}  // namespace octocosm
