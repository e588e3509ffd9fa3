#include "index/sampler.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <numeric>
#include <string>

#include "storage/error.h"

namespace octocosm {
namespace {

// splitmix64's finaliser: a bijection with good avalanche, enough to turn
// sequential IDs into independent-looking uniforms.
std::uint64_t Mix(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  x ^= x >> 31;
  return x;
}

// The population's weight in each point's fine density cell, and the total.
struct Density {
  std::vector<double> cell_weight;  // per point
  double total = 0;
  double cell_edge = 0;
};

Density EstimateDensity(std::span<const double> position, std::span<const double> weight,
                        std::span<const std::uint64_t> tie_break, NodeKey key, const Cube& cube, int bits) {
  const std::size_t m = weight.size();
  const int level = key.level();
  std::vector<std::uint32_t> fine(m);
  for (std::size_t i = 0; i < m; ++i) fine[i] = DensityCellIndex(&position[3 * i], key, cube, bits);
  // Summing in an order fixed by the points' values (not their positions in
  // the input) makes the sums, and so the sample, independent of input order.
  // A counting sort groups the points by fine cell in O(m); only the few
  // points sharing a cell need a comparison sort.
  const std::size_t cells = std::size_t{1} << (3 * bits);
  std::vector<std::uint32_t> start(cells + 1, 0);
  for (std::size_t i = 0; i < m; ++i) ++start[fine[i] + 1];
  for (std::size_t c = 0; c < cells; ++c) start[c + 1] += start[c];
  std::vector<std::uint32_t> order(m);
  {
    std::vector<std::uint32_t> next(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < m; ++i) order[next[fine[i]]++] = static_cast<std::uint32_t>(i);
  }
  for (std::size_t c = 0; c < cells; ++c) {
    if (start[c + 1] - start[c] < 2) continue;
    std::sort(order.begin() + start[c], order.begin() + start[c + 1], [&](std::uint32_t a, std::uint32_t b) {
      if (tie_break[a] != tie_break[b]) return tie_break[a] < tie_break[b];
      return weight[a] < weight[b];
    });
  }
  Density d;
  d.cell_weight.resize(m);
  d.cell_edge = cube.NodeSize(level + bits);
  for (std::size_t begin = 0; begin < m;) {
    std::size_t end = begin;
    double sum = 0;
    while (end < m && fine[order[end]] == fine[order[begin]]) sum += weight[order[end++]];
    for (std::size_t j = begin; j < end; ++j) d.cell_weight[order[j]] = sum;
    d.total += sum;
    begin = end;
  }
  return d;
}


void CheckInputs(std::span<const double> position, std::span<const double> weight, std::size_t ids,
                 const SamplerOptions& options) {
  if (position.size() != 3 * weight.size() || ids != weight.size()) {
    throw Error::InvalidArgument("sampler: " + std::to_string(position.size()) + " coordinates, " +
                                 std::to_string(weight.size()) + " weights and " + std::to_string(ids) +
                                 " IDs do not describe the same points");
  }
  if (!(options.alpha >= 0) || !std::isfinite(options.alpha)) {
    throw Error::InvalidArgument("sampler: density exponent alpha " + std::to_string(options.alpha) +
                                 " must be finite and >= 0");
  }
  if (options.density_grid_bits < 1 || options.density_grid_bits > 8) {
    throw Error::InvalidArgument("sampler: density grid bits " + std::to_string(options.density_grid_bits) +
                                 " must be in 1..8");
  }
  for (std::size_t i = 0; i < weight.size(); ++i) {
    if (!(weight[i] > 0) || !std::isfinite(weight[i])) {
      throw Error::InvalidArgument("sampler: weight of point " + std::to_string(i) + " is " +
                                   std::to_string(weight[i]) + ", must be finite and > 0");
    }
  }
}

}  // namespace

double SmoothingLengthFor(double weight, double cell_weight, double cell_edge, double node_size) {
  // (W / rho)^(1/3) = cell_edge * (W / cell_weight)^(1/3).
  const double h = kSmoothingEta * cell_edge * std::cbrt(weight / cell_weight);
  return std::clamp(h, node_size / 65536.0, node_size);
}

std::uint32_t DensityCellIndex(const double* position, NodeKey key, const Cube& cube, int bits) {
  const auto g = cube.GridCoords(position, key.level() + bits);
  const CellCoord cell = key.cell();
  // Coordinates relative to the node; the mask keeps the index in range even
  // for a point that lies outside the node (a caller's error).
  const std::uint64_t mask = (std::uint64_t{1} << bits) - 1;
  const std::uint64_t x = (g[0] - (std::uint64_t{cell.x} << bits)) & mask;
  const std::uint64_t y = (g[1] - (std::uint64_t{cell.y} << bits)) & mask;
  const std::uint64_t z = (g[2] - (std::uint64_t{cell.z} << bits)) & mask;
  return static_cast<std::uint32_t>(x | (y << bits) | (z << (2 * bits)));
}

std::uint64_t SamplingId(const double* position) {
  std::uint64_t h = 0x6a09e667f3bcc908ull;
  for (int a = 0; a < 3; ++a) h = Mix(h ^ std::bit_cast<std::uint64_t>(position[a]));
  return h;
}

std::uint64_t LevelSeed(std::uint64_t seed, int level) {
  return Mix(seed ^ (0x9e3779b97f4a7c15ull * static_cast<std::uint64_t>(level + 1)));
}

double PriorityUniform(std::uint64_t sampling_id, std::uint64_t seed) {
  const std::uint64_t h = Mix(sampling_id ^ Mix(seed + 0x9e3779b97f4a7c15ull));
  return static_cast<double>((h >> 11) + 1) * 0x1.0p-53;
}

std::vector<double> LeafSmoothingLengths(std::span<const double> position, std::span<const double> weight,
                                         NodeKey key, const Cube& cube, const SamplerOptions& options) {
  CheckInputs(position, weight, weight.size(), options);
  // Any fixed order works for the sums here; the weights alone break ties.
  const std::vector<std::uint64_t> no_ids(weight.size(), 0);
  const Density d = EstimateDensity(position, weight, no_ids, key, cube, options.density_grid_bits);
  const double node_size = cube.NodeSize(key.level());
  std::vector<double> h(weight.size());
  for (std::size_t i = 0; i < h.size(); ++i) h[i] = SmoothingLengthFor(weight[i], d.cell_weight[i], d.cell_edge, node_size);
  return h;
}

Sample SampleNode(std::span<const double> position, std::span<const double> weight,
                  std::span<const std::uint64_t> sampling_id, NodeKey key, const Cube& cube, std::size_t capacity,
                  const SamplerOptions& options) {
  CheckInputs(position, weight, sampling_id.size(), options);
  if (capacity == 0) throw Error::InvalidArgument("sampler: capacity must be at least 1");
  const std::size_t m = weight.size();
  const Density d = EstimateDensity(position, weight, sampling_id, key, cube, options.density_grid_bits);
  const double node_size = cube.NodeSize(key.level());
  Sample sample;

  if (m <= capacity) {
    sample.kept.resize(m);
    std::iota(sample.kept.begin(), sample.kept.end(), 0u);
    sample.weight.assign(weight.begin(), weight.end());
    sample.estimate = sample.weight;
    sample.smoothing.resize(m);
    for (std::size_t i = 0; i < m; ++i) {
      sample.smoothing[i] = SmoothingLengthFor(weight[i], d.cell_weight[i], d.cell_edge, node_size);
    }
    return sample;
  }

  // Importance relative to the node's total weight keeps the numbers near 1.
  std::vector<double> importance(m), priority(m);
  for (std::size_t i = 0; i < m; ++i) {
    importance[i] = weight[i] * std::pow(d.cell_weight[i] / d.total, -options.alpha);
    priority[i] = importance[i] / PriorityUniform(sampling_id[i], LevelSeed(options.seed, key.level()));
  }
  // Highest priority first; equal priorities (duplicate IDs) fall back to
  // the ID and then the input index, so the order is total.
  std::vector<std::uint32_t> order(m);
  std::iota(order.begin(), order.end(), 0u);
  const auto higher = [&](std::uint32_t a, std::uint32_t b) {
    if (priority[a] != priority[b]) return priority[a] > priority[b];
    if (sampling_id[a] != sampling_id[b]) return sampling_id[a] < sampling_id[b];
    return a < b;
  };
  std::nth_element(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(capacity), order.end(), higher);
  sample.threshold = priority[order[capacity]];
  order.resize(capacity);
  std::sort(order.begin(), order.end());
  sample.kept = std::move(order);

  // Unbiased estimates w_i * max(1, tau / s_i), then rescaled to the exact total.
  sample.weight.resize(capacity);
  long double estimated = 0;
  for (std::size_t j = 0; j < capacity; ++j) {
    const std::uint32_t i = sample.kept[j];
    sample.weight[j] = weight[i] * std::max(1.0, sample.threshold / importance[i]);
    estimated += sample.weight[j];
  }
  sample.estimate = sample.weight;
  const double scale = static_cast<double>(static_cast<long double>(d.total) / estimated);
  sample.smoothing.resize(capacity);
  for (std::size_t j = 0; j < capacity; ++j) {
    const std::uint32_t i = sample.kept[j];
    sample.weight[j] *= scale;
    sample.smoothing[j] = SmoothingLengthFor(sample.weight[j], d.cell_weight[i], d.cell_edge, node_size);
  }
  return sample;
}

}  // namespace octocosm
