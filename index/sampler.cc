#include "index/sampler.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include "base/error.h"
#include "base/hash.h"
#include "index/extended_sum.h"
#include "index/nth_largest.h"

namespace octocosm {
namespace {


// PriorityUniform in two steps, so that a node mixes its seed once, not once per point.
std::uint64_t MixedPrioritySeed(std::uint64_t seed) { return MixBits64(seed + kGoldenGamma); }
double PriorityUniformMixed(std::uint64_t sampling_id, std::uint64_t mixed_seed) {
  const std::uint64_t h = MixBits64(sampling_id ^ mixed_seed);
  return static_cast<double>((h >> 11) + 1) * 0x1.0p-53;
}

// The population's weight in each occupied fine density cell, which cell
// each point lies in, and the total.
struct Density {
  std::vector<std::uint32_t> cell_of;  // per point: index into cell_weight
  std::vector<double> cell_weight;     // per occupied fine cell, in the order the points reach them
  double total = 0;
  double cell_edge = 0;
};

// Numbers the fine cells of a node's density grid in the order its points
// first occupy them. The table from fine cell to number is held per thread
// across calls and cleared cell by cell when a numbering ends: a leaf of a
// few thousand points should not pay for filling 2^(3 bits) entries.
class OccupiedCellNumbering {
 public:
  // `most`: how many cells can be occupied (room is made for them up front).
  OccupiedCellNumbering(std::size_t fine_cells, std::size_t most)
      : number_of_(TableForThisThread(fine_cells)), occupied_(most + 1) {}  // + 1: the write past the last
  ~OccupiedCellNumbering() {
    for (std::size_t k = 0; k < count_; ++k) number_of_[occupied_[k]] = kUnoccupied;
  }
  OccupiedCellNumbering(const OccupiedCellNumbering&) = delete;
  OccupiedCellNumbering& operator=(const OccupiedCellNumbering&) = delete;

  // The number of fine cell `fine`: the next one when it is new. Without a
  // branch: whether a point opens a new cell is a coin toss in a sparse
  // node, and the branch on it was mispredicted that often.
  std::uint32_t Number(std::uint32_t fine) {
    const std::uint32_t known = number_of_[fine];
    const bool fresh = known == kUnoccupied;
    const std::uint32_t number = fresh ? static_cast<std::uint32_t>(count_) : known;
    number_of_[fine] = number;
    occupied_[count_] = fine;  // kept only when fresh: count_ moves on past it
    count_ += fresh ? 1 : 0;
    return number;
  }
  std::size_t count() const { return count_; }

 private:
  static constexpr std::uint32_t kUnoccupied = UINT32_MAX;
  static std::vector<std::uint32_t>& TableForThisThread(std::size_t fine_cells) {
    thread_local std::vector<std::uint32_t> table;
    if (table.size() < fine_cells) table.resize(fine_cells, kUnoccupied);
    return table;
  }

  std::vector<std::uint32_t>& number_of_;
  std::vector<std::uint32_t> occupied_;  // fine cells, by number; the first count_ are occupied
  std::size_t count_ = 0;
};

Density EstimateDensity(std::span<const GridPoint> grid, std::span<const double> weight, NodeKey key,
                        const Cube& cube, int bits) {
  const std::size_t m = weight.size();
  const int level = key.level();
  const CellCoord cell = key.cell();
  const std::uint64_t mask = (std::uint64_t{1} << bits) - 1;
  const std::size_t fine_cells = std::size_t{1} << (3 * bits);
  // Sized up front: most points of a small node occupy a cell of their own,
  // and growing the vectors there cost a fifth of this function's time.
  const std::size_t most_cells = std::min(m, fine_cells);
  OccupiedCellNumbering numbering(fine_cells, most_cells);
  Density d;
  d.cell_weight.resize(most_cells, 0.0);  // cut to the occupied cells below
  d.cell_of.resize(m);
  d.cell_edge = cube.NodeSize(level + bits);
  // Each cell's weight is summed in the order of the points. The octree
  // builder hands over its points in an order fixed by their values (a leaf's
  // by particle ID, a parent's octant by octant), so its sums do not depend
  // on how the input was read or chunked; a caller that permutes the points
  // changes the sums only by rounding.
  for (std::size_t i = 0; i < m; ++i) {
    // Coordinates relative to the node; the mask keeps the index in range
    // even for a point that lies outside the node (a caller's error).
    const std::uint64_t x = (GridAxisAt(grid[i], 0, level + bits) - (std::uint64_t{cell.x} << bits)) & mask;
    const std::uint64_t y = (GridAxisAt(grid[i], 1, level + bits) - (std::uint64_t{cell.y} << bits)) & mask;
    const std::uint64_t z = (GridAxisAt(grid[i], 2, level + bits) - (std::uint64_t{cell.z} << bits)) & mask;
    const std::uint32_t number = numbering.Number(static_cast<std::uint32_t>(x | (y << bits) | (z << (2 * bits))));
    d.cell_weight[number] += weight[i];
    d.cell_of[i] = number;
  }
  d.cell_weight.resize(numbering.count());
  for (const double w : d.cell_weight) d.total += w;
  return d;
}

// A direct-mapped memo of a function of two doubles: the last value computed
// for each of 1024 slots, a slot chosen by a hash of the pair. The sampler's
// costly per-point functions (a cbrt, a pow) take few distinct pairs in a
// node, so this saves most calls with the same results.
class PairMemo {
 public:
  PairMemo() { first_.fill(std::numeric_limits<double>::quiet_NaN()); }  // NaN matches nothing: all slots empty

  template <typename F>
  double Get(double first, double second, const F& f) {
    const std::uint64_t a = std::bit_cast<std::uint64_t>(first);
    const std::uint64_t b = std::bit_cast<std::uint64_t>(second);
    const std::size_t slot = static_cast<std::size_t>(MixBits64(a ^ (b * kGoldenGamma)) % kSlots);
    if (first_[slot] != first || second_[slot] != second) {
      first_[slot] = first;
      second_[slot] = second;
      value_[slot] = f(first, second);
    }
    return value_[slot];
  }

 private:
  static constexpr std::size_t kSlots = 1024;
  std::array<double, kSlots> first_;
  std::array<double, kSlots> second_;
  std::array<double, kSlots> value_;
};

// Step 5 for the points of one node. A point's length depends only on its
// weight and its density cell's weight, and few such pairs are distinct:
// equal-mass particles in cells of one, two, three ... particles share a
// handful of them, and a parent's points that fell below the threshold share
// their cell's. So they are memoised: far fewer cbrt calls (glibc's, with a
// frexp and an ldexp call inside), with the same results.
class SmoothingCache {
 public:
  SmoothingCache(const Density& density, double node_size) : density_(density), node_size_(node_size) {}

  double For(std::size_t point, double weight) {
    return memo_.Get(weight, density_.cell_weight[density_.cell_of[point]], [this](double w, double cell_weight) {
      return SmoothingLengthFor(w, cell_weight, density_.cell_edge, node_size_);
    });
  }

 private:
  const Density& density_;
  double node_size_;
  PairMemo memo_;
};

void CheckInputs(std::size_t points, std::span<const double> weight, std::size_t ids, const SamplerOptions& options) {
  if (points != weight.size() || ids != weight.size()) {
    throw Error::InvalidArgument("sampler: " + std::to_string(points) + " points, " + std::to_string(weight.size()) +
                                 " weights and " + std::to_string(ids) + " IDs do not describe the same points");
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

// The points' GridPoints, for the callers that give positions.
std::vector<GridPoint> GridOf(std::span<const double> position, const Cube& cube) {
  if (position.size() % 3 != 0) {
    throw Error::InvalidArgument("sampler: " + std::to_string(position.size()) + " coordinates are not x,y,z triples");
  }
  std::vector<GridPoint> grid(position.size() / 3);
  for (std::size_t i = 0; i < grid.size(); ++i) grid[i] = cube.FinestGridCoords(&position[3 * i]);
  return grid;
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
  for (int a = 0; a < 3; ++a) h = MixBits64(h ^ std::bit_cast<std::uint64_t>(position[a]));
  return h;
}

std::uint64_t LevelSeed(std::uint64_t seed, int level) {
  return MixBits64(seed ^ (kGoldenGamma * static_cast<std::uint64_t>(level + 1)));
}

double PriorityUniform(std::uint64_t sampling_id, std::uint64_t seed) {
  return PriorityUniformMixed(sampling_id, MixedPrioritySeed(seed));
}

std::vector<double> LeafSmoothingLengths(std::span<const GridPoint> grid, std::span<const double> weight, NodeKey key,
                                         const Cube& cube, const SamplerOptions& options) {
  CheckInputs(grid.size(), weight, weight.size(), options);
  const Density d = EstimateDensity(grid, weight, key, cube, options.density_grid_bits);
  const double node_size = cube.NodeSize(key.level());
  SmoothingCache smoothing(d, node_size);
  std::vector<double> h(weight.size());
  for (std::size_t i = 0; i < h.size(); ++i) h[i] = smoothing.For(i, weight[i]);
  return h;
}

std::vector<double> LeafSmoothingLengths(std::span<const double> position, std::span<const double> weight,
                                         NodeKey key, const Cube& cube, const SamplerOptions& options) {
  return LeafSmoothingLengths(GridOf(position, cube), weight, key, cube, options);
}

Sample SampleNode(std::span<const double> position, std::span<const double> weight,
                  std::span<const std::uint64_t> sampling_id, NodeKey key, const Cube& cube, std::size_t capacity,
                  const SamplerOptions& options) {
  return SampleNode(GridOf(position, cube), weight, sampling_id, key, cube, capacity, options);
}

Sample SampleNode(std::span<const GridPoint> grid, std::span<const double> weight,
                  std::span<const std::uint64_t> sampling_id, NodeKey key, const Cube& cube, std::size_t capacity,
                  const SamplerOptions& options) {
  CheckInputs(grid.size(), weight, sampling_id.size(), options);
  if (capacity == 0) throw Error::InvalidArgument("sampler: capacity must be at least 1");
  const std::size_t m = weight.size();
  const Density d = EstimateDensity(grid, weight, key, cube, options.density_grid_bits);
  const double node_size = cube.NodeSize(key.level());
  Sample sample;

  if (m <= capacity) {
    sample.kept.resize(m);
    std::iota(sample.kept.begin(), sample.kept.end(), 0u);
    sample.weight.assign(weight.begin(), weight.end());
    sample.estimate = sample.weight;
    SmoothingCache smoothing(d, node_size);
    sample.smoothing.resize(m);
    for (std::size_t i = 0; i < m; ++i) sample.smoothing[i] = smoothing.For(i, weight[i]);
    return sample;
  }

  // Importance relative to the node's total weight keeps the numbers near 1.
  // The density factor is the same for every point of a fine cell, and for
  // every cell of the same weight (cells of one, two, three equal-mass
  // points): about one pow per distinct cell weight.
  std::vector<double> cell_factor(d.cell_weight.size());
  PairMemo factor_of;
  const auto factor = [&options](double cell_weight, double total) { return std::pow(cell_weight / total, -options.alpha); };
  for (std::size_t c = 0; c < cell_factor.size(); ++c) cell_factor[c] = factor_of.Get(d.cell_weight[c], d.total, factor);
  std::vector<double> importance(m), priority(m);
  const std::uint64_t mixed_seed = MixedPrioritySeed(LevelSeed(options.seed, key.level()));
  for (std::size_t i = 0; i < m; ++i) {
    importance[i] = weight[i] * cell_factor[d.cell_of[i]];
    priority[i] = importance[i] / PriorityUniformMixed(sampling_id[i], mixed_seed);
  }
  // The `capacity` highest priorities are kept; among equal priorities
  // (duplicate IDs) the lower ID, then the lower index, so the choice is
  // total. The threshold is selected among the priorities themselves, not
  // through an index order, so the selection is a pass over contiguous
  // doubles; the rare points that tie with it are ordered apart.
  sample.threshold = NthLargest(priority, capacity);
  std::size_t above = 0;
  for (std::size_t i = 0; i < m; ++i) above += priority[i] > sample.threshold ? 1 : 0;
  std::vector<std::uint32_t> tied;
  for (std::size_t i = 0; i < m; ++i) {
    if (priority[i] == sample.threshold) tied.push_back(static_cast<std::uint32_t>(i));
  }
  // At least one tied point (the threshold's own) is left out.
  std::sort(tied.begin(), tied.end(), [&](std::uint32_t a, std::uint32_t b) {
    return sampling_id[a] != sampling_id[b] ? sampling_id[a] < sampling_id[b] : a < b;
  });
  std::vector<std::uint8_t> is_kept(m, 0);
  for (std::size_t j = 0; j < capacity - above; ++j) is_kept[tied[j]] = 1;
  // The kept indices in ascending order, in one sweep without a branch:
  // whether a point is kept is a coin toss, and the branch on it was
  // mispredicted that often (a fifth of this function's time). Every index
  // is written, and the next overwrites it unless it was kept; + 1: room for
  // the writes after the last kept point.
  sample.kept.resize(capacity + 1);
  std::size_t kept = 0;
  for (std::size_t i = 0; i < m; ++i) {
    sample.kept[kept] = static_cast<std::uint32_t>(i);
    kept += (priority[i] > sample.threshold) | is_kept[i];
  }
  sample.kept.resize(capacity);

  // Unbiased estimates w_i * max(1, tau / s_i), then rescaled to the exact total.
  sample.weight.resize(capacity);
  for (std::size_t j = 0; j < capacity; ++j) {
    const std::uint32_t i = sample.kept[j];
    sample.weight[j] = weight[i] * std::max(1.0, sample.threshold / importance[i]);
  }
  sample.estimate = sample.weight;
  const double scale = static_cast<double>(static_cast<long double>(d.total) / ExtendedSum(sample.weight));
  SmoothingCache smoothing(d, node_size);
  sample.smoothing.resize(capacity);
  for (std::size_t j = 0; j < capacity; ++j) {
    sample.weight[j] *= scale;
    sample.smoothing[j] = smoothing.For(sample.kept[j], sample.weight[j]);
  }
  return sample;
}

}  // namespace octocosm
