#include "index/aggregator.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <queue>
#include <span>

#include "base/error.h"

namespace octocosm {
namespace {

// A node is drawn where its mean point spacing projects to a few pixels: a
// pixel is taken as this fraction of the spacing when judging which cells'
// spread would show.
constexpr double kPixelsPerSpacing = 8;

// Mass-weighted sums over members, their offsets in node edges from a
// reference point.
struct Sums {
  std::uint32_t points = 0;
  double mass = 0;
  double first[3] = {0, 0, 0};            // sum w d
  double second[6] = {0, 0, 0, 0, 0, 0};  // sum w d d^T: xx, yy, zz, xy, xz, yz
  double own = 0;                         // sum w v (own blob variance)

  void Add(double w, const double d[3], double v) {
    ++points;
    mass += w;
    for (int a = 0; a < 3; ++a) first[a] += w * d[a];
    second[0] += w * d[0] * d[0];
    second[1] += w * d[1] * d[1];
    second[2] += w * d[2] * d[2];
    second[3] += w * d[0] * d[1];
    second[4] += w * d[0] * d[2];
    second[5] += w * d[1] * d[2];
    own += w * v;
  }
  void Add(const Sums& o) {
    points += o.points;
    mass += o.mass;
    for (int a = 0; a < 3; ++a) first[a] += o.first[a];
    for (int i = 0; i < 6; ++i) second[i] += o.second[i];
    own += o.own;
  }
  // Summed squared distance of the members from their centre of mass.
  double SquaredSpread() const {
    const double centre2 = first[0] * first[0] + first[1] * first[1] + first[2] * first[2];
    return std::max(0.0, second[0] + second[1] + second[2] - centre2 / mass);
  }
  double Error(double pixel2) const {
    const double spread = SquaredSpread() / (3 * mass);  // per axis
    const double blobs = spread + own / mass + pixel2;
    return blobs > 0 ? mass * spread / blobs : 0;
  }
};

// What the search for a cut needs of the members in one bin.
struct BinSums {
  std::uint32_t points = 0;
  double mass = 0;
  double first[3] = {0, 0, 0};
  double second = 0;  // sum w |d|^2

  void Add(const BinSums& o) {
    points += o.points;
    mass += o.mass;
    for (int a = 0; a < 3; ++a) first[a] += o.first[a];
    second += o.second;
  }
  // Summed squared distance from the centre of mass of these members, and
  // of the others of `all`.
  double SquaredSpread() const {
    return std::max(0.0, second - (first[0] * first[0] + first[1] * first[1] + first[2] * first[2]) / mass);
  }
  double SquaredSpreadOfRest(const BinSums& all) const {
    double centre2 = 0;
    for (int a = 0; a < 3; ++a) centre2 += (all.first[a] - first[a]) * (all.first[a] - first[a]);
    return std::max(0.0, all.second - second - centre2 / (all.mass - mass));
  }
};

struct Cell {
  std::uint32_t begin, end;  // range of the cutter's members
  double error;              // what drawing it as one blob would cost (aggregator.h)
  double reference[3];       // the point `sums` measures offsets from, in node edges
  Sums sums;
  int copy = 0;              // which of the cutter's two copies of the members holds its range in order
};

// A member as the cutter keeps it: where it lies in node edges from the
// node's corner, its weight and own blob variance, and its population
// index. Members are moved, not indexed, so that every pass over a cell reads
// memory in order.
struct Member {
  double d[3];
  double weight;
  double own;
  std::uint32_t index;
};

// Cuts cells of a population in two (aggregator.h). The members live in two
// copies: a cut reads its cell's range from one and writes the halves into
// the other, so no pass copies them back.
class CellCutter {
 public:
  CellCutter(std::vector<Member> members, std::size_t capacity)
      : pixel2_(std::pow(1.0 / (std::cbrt(static_cast<double>(capacity)) * kPixelsPerSpacing), 2)),
        bin_(members.size()) {
    copies_[1].resize(members.size());
    copies_[0] = std::move(members);
    filled_.reserve(kCutBins);
  }

  // A cell's members, in its order.
  std::span<const Member> MembersOf(const Cell& cell) const {
    return std::span<const Member>(copies_[cell.copy]).subspan(cell.begin, cell.end - cell.begin);
  }

  Cell Measure(std::uint32_t begin, std::uint32_t end) const {
    const std::vector<Member>& members = copies_[0];
    Cell cell{begin, end, 0, {}, {}};
    for (int a = 0; a < 3; ++a) cell.reference[a] = members[begin].d[a];
    for (std::uint32_t k = begin; k < end; ++k) {
      const Member& p = members[k];
      const double d[3] = {p.d[0] - cell.reference[0], p.d[1] - cell.reference[1], p.d[2] - cell.reference[2]};
      cell.sums.Add(p.weight, d, p.own);
    }
    cell.error = cell.sums.Error(pixel2_);
    return cell;
  }

  // Cuts `cell` across its principal axis where the halves' summed squared
  // spread is least; false when its members cannot be told apart along it.
  bool Cut(const Cell& cell, Cell& low, Cell& high) {
    // The centre and covariance from the cell's sums (about a point inside
    // the cell, so that a small cell keeps its precision).
    const Sums& sums = cell.sums;
    double mean[3], c[3][3];
    for (int a = 0; a < 3; ++a) mean[a] = sums.first[a] / sums.mass;
    const int entry[3][3] = {{0, 3, 4}, {3, 1, 5}, {4, 5, 2}};
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) c[a][b] = sums.second[entry[a][b]] / sums.mass - mean[a] * mean[b];
    }
    for (int a = 0; a < 3; ++a) mean[a] += cell.reference[a];
    double covariance[3][3];
    std::copy(&c[0][0], &c[0][0] + 9, &covariance[0][0]);
    int widest = 0;
    for (int a = 1; a < 3; ++a) widest = c[a][a] > c[widest][widest] ? a : widest;
    if (!(c[widest][widest] > 0)) return false;
    // C^16 (squared four times, scaled by its largest diagonal entry each
    // time) times the axis of largest variance: the principal axis, to
    // within (second / first eigenvalue)^16.
    for (int squaring = 0; squaring < 4; ++squaring) {
      double square[3][3] = {};
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) {
          for (int k = 0; k < 3; ++k) square[a][b] += c[a][k] * c[k][b];
        }
      }
      const double scale = std::max({square[0][0], square[1][1], square[2][2]});
      if (!(scale > 0) || !std::isfinite(scale)) break;
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) c[a][b] = square[a][b] / scale;
      }
    }
    double axis[3] = {c[0][widest], c[1][widest], c[2][widest]};
    const double norm = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
    if (!(norm > 0) || !std::isfinite(norm)) return false;
    for (double& x : axis) x /= norm;

    // The members' projections binned over four standard deviations on
    // either side of the centre, those beyond in the end bins (whose sums
    // stay exact: the cut is sought only between bins).
    double variance = 0;
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) variance += axis[a] * covariance[a][b] * axis[b];
    }
    if (!(variance > 0)) return false;
    const double lo = -4 * std::sqrt(variance), hi = -lo;
    const auto project = [&](const Member& p, double d[3]) {
      for (int a = 0; a < 3; ++a) d[a] = p.d[a] - mean[a];
      return d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2];
    };
    // Bins enough to place a cut between any two of a small cell's members
    // nearly where the best would be, at most kCutBins.
    const std::uint32_t size = cell.end - cell.begin;
    const int bin_count = static_cast<int>(std::min<std::uint32_t>(kCutBins, 4 * size));
    const double per_bin = bin_count / (hi - lo);
    // Members lie in space in about the order they come, so neighbours often
    // fall into one bin, and each addition to it would wait for the one
    // before: members alternate between two sets of bins, summed once the
    // pass is done.
    const std::vector<Member>& from = copies_[cell.copy];
    for (std::uint32_t k = cell.begin; k < cell.end; ++k) {
      const Member& p = from[k];
      double d[3];
      const double t = project(p, d);
      const int b = std::clamp(static_cast<int>((t - lo) * per_bin), 0, bin_count - 1);
      bin_[k] = static_cast<std::uint16_t>(b);
      BinSums& bin = bins_[static_cast<std::size_t>(b) + kCutBins * (k & 1)];
      occupied_[static_cast<std::size_t>(b) / 64] |= std::uint64_t{1} << (b % 64);
      ++bin.points;
      bin.mass += p.weight;
      for (int a = 0; a < 3; ++a) bin.first[a] += p.weight * d[a];
      bin.second += p.weight * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    }

    // The bins that hold members, in order, and the bins left empty for the
    // next cut. A small cell has four bins a member, most of them empty:
    // walking only the others keeps the search linear in the members.
    filled_.clear();
    for (std::size_t word = 0; word < occupied_.size(); ++word) {
      for (std::uint64_t bits = occupied_[word]; bits != 0; bits &= bits - 1) {
        filled_.push_back(static_cast<std::uint16_t>(64 * word + static_cast<std::size_t>(std::countr_zero(bits))));
      }
      occupied_[word] = 0;
    }

    // The boundary between bins that leaves the least squared spread (none
    // when every member fell into one bin).
    BinSums all, below;
    for (const std::uint16_t b : filled_) {
      bins_[b].Add(bins_[b + kCutBins]);
      bins_[b + kCutBins] = BinSums{};
      all.Add(bins_[b]);
    }
    double best = INFINITY;
    int cut = 0;
    for (const std::uint16_t b : filled_) {
      below.Add(bins_[b]);
      if (below.points == all.points) break;
      const double spread = below.SquaredSpread() + below.SquaredSpreadOfRest(all);
      if (spread < best) {
        best = spread;
        cut = b + 1;
      }
    }
    for (const std::uint16_t b : filled_) bins_[b] = BinSums{};
    if (cut == 0) return false;

    // The members below the cut first, in their order; those above after
    // them, in reverse order. Each half's sums, about the cell's centre.
    Sums low_sums, high_sums;
    const int other = 1 - cell.copy;
    std::vector<Member>& to = copies_[other];
    std::uint32_t front = cell.begin, back = cell.end;
    for (std::uint32_t k = cell.begin; k < cell.end; ++k) {
      const Member& p = from[k];
      const double d[3] = {p.d[0] - mean[0], p.d[1] - mean[1], p.d[2] - mean[2]};
      if (bin_[k] < cut) {
        low_sums.Add(p.weight, d, p.own);
        to[front++] = p;
      } else {
        high_sums.Add(p.weight, d, p.own);
        to[--back] = p;
      }
    }
    const std::uint32_t middle = front;
    low = {cell.begin, middle, low_sums.Error(pixel2_), {mean[0], mean[1], mean[2]}, low_sums, other};
    high = {middle, cell.end, high_sums.Error(pixel2_), {mean[0], mean[1], mean[2]}, high_sums, other};
    return true;
  }

 private:
  std::array<std::vector<Member>, 2> copies_;
  double pixel2_;                   // a pixel where the node is drawn, squared, in node edges
  std::vector<std::uint16_t> bin_;  // each member's bin, during a cut
  std::vector<BinSums> bins_ = std::vector<BinSums>(2 * kCutBins);  // two sets, all empty between cuts
  std::array<std::uint64_t, kCutBins / 64> occupied_{};              // which bins hold members, during a cut
  std::vector<std::uint16_t> filled_;                                  // the bins that hold members, in order
};

}  // namespace

double KernelRadiusForVariance(double variance) { return std::sqrt(std::max(variance, 0.0) / kKernelVariancePerH2); }

Clusters ClusterPopulation(std::span<const GridPoint> grid, std::span<const double> weight,
                           std::span<const double> own_variance, std::span<const std::uint8_t> type, NodeKey key,
                           std::size_t capacity) {
  if (grid.size() != weight.size() || (!type.empty() && type.size() != grid.size()) ||
      (!own_variance.empty() && own_variance.size() != grid.size())) {
    throw Error::InvalidArgument("ClusterPopulation: " + std::to_string(grid.size()) + " grid points but " +
                                 std::to_string(weight.size()) + " weights, " + std::to_string(own_variance.size()) +
                                 " blob variances and " + std::to_string(type.size()) + " types");
  }
  if (capacity < 8) {
    throw Error::InvalidArgument("ClusterPopulation: a capacity of " + std::to_string(capacity) +
                                 " cannot hold one cluster per octant");
  }
  std::size_t types = 0;
  if (!type.empty()) {
    std::array<bool, 256> present{};
    for (const std::uint8_t t : type) present[t] = true;
    types = static_cast<std::size_t>(std::count(present.begin(), present.end(), true));
  }
  if (types > 1 && capacity < 8 * types) {
    throw Error::InvalidArgument("ClusterPopulation: a capacity of " + std::to_string(capacity) +
                                 " cannot hold one cluster per octant and type (" + std::to_string(types) + " types)");
  }
  const std::size_t m = grid.size();
  if (m > UINT32_MAX) throw Error::InvalidArgument("ClusterPopulation: more than 2^32 - 1 points");
  std::vector<Cell> cells;
  cells.reserve(8 * 256 + 2 * capacity);  // the first cells, and two for each cut

  // The costliest cell first; among equal errors the first in member order
  // (a cell's place there depends only on its members' positions, not on
  // the input's order), so the result is deterministic. The queue holds
  // what it compares, so that it never reaches into `cells`.
  struct Queued {
    double error;
    std::uint32_t begin, cell;
    bool operator<(const Queued& o) const { return error != o.error ? error < o.error : begin > o.begin; }
  };
  std::priority_queue<Queued> costliest;
  std::vector<std::uint32_t> final_cells;
  // A cell of one member is final: it goes straight there, not through the
  // queue.
  const auto enqueue = [&](const Cell& cell) {
    cells.push_back(cell);
    const auto index = static_cast<std::uint32_t>(cells.size() - 1);
    if (cell.end - cell.begin == 1) {
      final_cells.push_back(index);
    } else {
      costliest.push({cell.error, cell.begin, index});
    }
  };
  // The first cut: the node's octants, and inside each the particle types,
  // so that every cluster is of one type (colour by type stays exact).
  std::vector<Member> members(m);
  std::vector<std::uint32_t> count_by(8 * 256 + 1, 0);
  if (m > 0) {
    const auto first_cell = [&](std::uint32_t i) {
      return OctantAt(grid[i], key.level()) * 256 + (type.empty() ? 0 : type[i]);
    };
    for (std::size_t i = 0; i < m; ++i) ++count_by[first_cell(static_cast<std::uint32_t>(i)) + 1];
    for (std::size_t b = 0; b < 8 * 256; ++b) count_by[b + 1] += count_by[b];
    std::vector<std::uint32_t> next(count_by.begin(), count_by.end() - 1);
    const double edge = std::ldexp(1.0, kFinestGridBits - key.level());  // in grid units
    double corner[3];
    for (int a = 0; a < 3; ++a) corner[a] = static_cast<double>(GridAxisAt(grid[0], a, key.level())) * edge;
    for (std::size_t i = 0; i < m; ++i) {
      Member& p = members[next[first_cell(static_cast<std::uint32_t>(i))]++];
      for (int a = 0; a < 3; ++a) p.d[a] = (static_cast<double>(grid[i][a]) - corner[a]) / edge;
      p.weight = weight[i];
      p.own = own_variance.empty() ? 0.0 : own_variance[i];
      p.index = static_cast<std::uint32_t>(i);
    }
  }
  CellCutter cutter(std::move(members), capacity);
  std::size_t count = 0;
  for (std::size_t b = 0; b < 8 * 256; ++b) {
    if (count_by[b] == count_by[b + 1]) continue;
    enqueue(cutter.Measure(count_by[b], count_by[b + 1]));
    ++count;
  }
  while (!costliest.empty()) {
    const std::uint32_t top = costliest.top().cell;
    const Cell& cell = cells[top];  // stays put: `cells` has room for every cell
    Cell low{}, high{};
    if (count + 1 > capacity) break;  // the partition left the cell's members together
    costliest.pop();
    if (!cutter.Cut(cell, low, high)) {
      final_cells.push_back(top);
      continue;
    }
    ++count;
    enqueue(low);
    enqueue(high);
  }
  while (!costliest.empty()) {
    final_cells.push_back(costliest.top().cell);
    costliest.pop();
  }
  // Member order groups the cells by the node's octants.
  std::sort(final_cells.begin(), final_cells.end(),
            [&](std::uint32_t a, std::uint32_t b) { return cells[a].begin < cells[b].begin; });

  Clusters out;
  out.member.reserve(m);
  out.begin.reserve(final_cells.size() + 1);
  for (const std::uint32_t c : final_cells) {
    out.begin.push_back(static_cast<std::uint32_t>(out.member.size()));
    const std::size_t first = out.member.size();
    for (const Member& p : cutter.MembersOf(cells[c])) out.member.push_back(p.index);
    std::sort(out.member.begin() + static_cast<std::ptrdiff_t>(first), out.member.end());
  }
  out.begin.push_back(static_cast<std::uint32_t>(out.member.size()));
  return out;
}

}  // namespace octocosm
