#include "accuracy/sample_score.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "base/error.h"

namespace octocosm::accuracy {
namespace {

// Quantile q of sorted values, interpolating between neighbours.
double Quantile(const std::vector<double>& sorted, double q) {
  if (sorted.empty()) return 0;
  const double at = q * static_cast<double>(sorted.size() - 1);
  const auto below = static_cast<std::size_t>(std::floor(at));
  const std::size_t above = std::min(below + 1, sorted.size() - 1);
  return sorted[below] + (at - static_cast<double>(below)) * (sorted[above] - sorted[below]);
}

ErrorDistribution Distribution(std::vector<double> errors) {
  ErrorDistribution d;
  d.voxels = errors.size();
  if (errors.empty()) return d;
  long double sum = 0, sum2 = 0;
  for (const double r : errors) sum += r, sum2 += static_cast<long double>(r) * r;
  const long double count = static_cast<long double>(errors.size());
  d.mean = static_cast<double>(sum / count);
  if (errors.size() > 1) {
    const long double variance = std::max(0.0L, (sum2 - sum * sum / count) / (count - 1));
    d.standard_error = static_cast<double>(std::sqrt(variance / count));
  }
  std::sort(errors.begin(), errors.end());
  d.p05 = Quantile(errors, 0.05);
  d.p25 = Quantile(errors, 0.25);
  d.median = Quantile(errors, 0.5);
  d.p75 = Quantile(errors, 0.75);
  d.p95 = Quantile(errors, 0.95);
  return d;
}

}  // namespace

int VoxelBitsPerNode(std::size_t capacity) {
  int bits = 0;
  while ((std::size_t{1} << (3 * bits)) < capacity) ++bits;
  return bits;
}

SampleScore ScoreSample(const VoxelCensus& census, const Subsample& sample) {
  const std::size_t n = census.voxel_of.size();
  if (sample.size() == 0 || sample.weight.size() != sample.size()) {
    throw Error::InvalidArgument("ScoreSample: the sample is empty or its weights do not match its points");
  }
  std::vector<double> estimate(census.voxels(), 0.0);
  std::vector<bool> hit(census.voxels(), false);
  for (std::size_t k = 0; k < sample.size(); ++k) {
    if (sample.index[k] >= n) {
      throw Error::InvalidArgument("ScoreSample: sample point " + std::to_string(k) + " has index " +
                                   std::to_string(sample.index[k]) + " of " + std::to_string(n) + " points");
    }
    const std::uint32_t v = census.voxel_of[sample.index[k]];
    estimate[v] += sample.weight[k];
    hit[v] = true;
  }
  SampleScore score;
  score.points = sample.size();
  score.voxels = census.voxels();
  score.sparse_below = static_cast<double>(n) / static_cast<double>(sample.size());
  std::vector<double> all, sparse, dense;
  all.reserve(census.voxels());
  std::size_t kept = 0, sparse_kept = 0;
  double dropped = 0;
  for (std::size_t v = 0; v < census.voxels(); ++v) {
    const double r = estimate[v] / census.mass[v] - 1;
    const bool is_sparse = census.count[v] < score.sparse_below;
    all.push_back(r);
    (is_sparse ? sparse : dense).push_back(r);
    kept += hit[v];
    if (is_sparse) sparse_kept += hit[v];
    if (!hit[v]) dropped += census.mass[v];
  }
  score.sparse_voxels = sparse.size();
  score.voxels_kept = static_cast<double>(kept) / static_cast<double>(census.voxels());
  score.sparse_voxels_kept = sparse.empty() ? 0 : static_cast<double>(sparse_kept) / static_cast<double>(sparse.size());
  score.mass_dropped = dropped / census.total_mass;
  score.all = Distribution(std::move(all));
  score.sparse = Distribution(std::move(sparse));
  score.dense = Distribution(std::move(dense));
  return score;
}

}  // namespace octocosm::accuracy
