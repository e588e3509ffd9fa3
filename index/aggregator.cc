#include "index/aggregator.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <queue>

#include "base/error.h"

namespace octocosm {
namespace {

struct Cell {
  std::uint32_t begin, end;  // range of `member`
  int level;                 // the cell is a node at this level
  double mass;
};

}  // namespace

double KernelRadiusForVariance(double variance) {
  return std::sqrt(std::max(variance, 0.0) / kKernelVariancePerH2);
}

Clusters ClusterPopulation(std::span<const GridPoint> grid, std::span<const double> weight,
                           std::span<const std::uint8_t> type, NodeKey key, std::size_t capacity) {
  if (grid.size() != weight.size() || (!type.empty() && type.size() != grid.size())) {
    throw Error::InvalidArgument("ClusterPopulation: " + std::to_string(grid.size()) + " grid points but " +
                                 std::to_string(weight.size()) + " weights");
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
  std::vector<std::uint32_t> member(m), scratch(m);
  for (std::size_t i = 0; i < m; ++i) member[i] = static_cast<std::uint32_t>(i);
  std::vector<Cell> cells;

  // Splits `cell` into its octants (in place in `member`, stable), returning
  // the non-empty ones.
  const auto split = [&](const Cell& cell) {
    std::array<std::uint32_t, 9> count{};
    for (std::uint32_t k = cell.begin; k < cell.end; ++k) ++count[OctantAt(grid[member[k]], cell.level) + 1];
    for (int o = 0; o < 8; ++o) count[o + 1] += count[o];
    std::array<std::uint32_t, 8> next{};
    for (int o = 0; o < 8; ++o) next[o] = cell.begin + count[o];
    for (std::uint32_t k = cell.begin; k < cell.end; ++k) scratch[next[OctantAt(grid[member[k]], cell.level)]++] = member[k];
    std::copy(scratch.begin() + cell.begin, scratch.begin() + cell.end, member.begin() + cell.begin);
    std::vector<Cell> children;
    for (int o = 0; o < 8; ++o) {
      const std::uint32_t b = cell.begin + count[o], e = cell.begin + count[o + 1];
      if (b == e) continue;
      double mass = 0;
      for (std::uint32_t k = b; k < e; ++k) mass += weight[member[k]];
      children.push_back({b, e, cell.level + 1, mass});
    }
    return children;
  };

  // The heaviest cell first; among equal masses the first in member order
  // (a cell's place there depends only on its position, not on the input's
  // order), so the result is deterministic.
  const auto lighter = [&](std::uint32_t a, std::uint32_t b) {
    return cells[a].mass != cells[b].mass ? cells[a].mass < cells[b].mass : cells[a].begin > cells[b].begin;
  };
  std::priority_queue<std::uint32_t, std::vector<std::uint32_t>, decltype(lighter)> heaviest(lighter);
  std::vector<std::uint32_t> final_cells;
  std::size_t count = 0;
  if (m > 0) {
    // The first cut: the node's octants, and inside each the particle types,
    // so that every cluster is of one type (colour by type stays exact).
    const auto first_cell = [&](std::uint32_t i) {
      return OctantAt(grid[i], key.level()) * 256 + (type.empty() ? 0 : type[i]);
    };
    std::vector<std::uint32_t> count_by(8 * 256 + 1, 0);
    for (std::size_t i = 0; i < m; ++i) ++count_by[first_cell(static_cast<std::uint32_t>(i)) + 1];
    for (std::size_t b = 0; b < 8 * 256; ++b) count_by[b + 1] += count_by[b];
    std::vector<std::uint32_t> next(count_by.begin(), count_by.end() - 1);
    for (std::size_t i = 0; i < m; ++i) member[next[first_cell(static_cast<std::uint32_t>(i))]++] = static_cast<std::uint32_t>(i);
    for (std::size_t b = 0; b < 8 * 256; ++b) {
      if (count_by[b] == count_by[b + 1]) continue;
      double mass = 0;
      for (std::uint32_t k = count_by[b]; k < count_by[b + 1]; ++k) mass += weight[member[k]];
      cells.push_back({count_by[b], count_by[b + 1], key.level() + 1, mass});
      heaviest.push(static_cast<std::uint32_t>(cells.size() - 1));
      ++count;
    }
  }
  while (!heaviest.empty()) {
    const std::uint32_t top = heaviest.top();
    const Cell cell = cells[top];
    if (cell.end - cell.begin == 1 || cell.level >= kFinestGridBits - 1) {
      heaviest.pop();
      final_cells.push_back(top);
      continue;
    }
    std::vector<Cell> children = split(cell);
    if (count - 1 + children.size() > capacity) break;  // the partition left the cell's members together
    heaviest.pop();
    count += children.size() - 1;
    for (const Cell& child : children) {
      cells.push_back(child);
      heaviest.push(static_cast<std::uint32_t>(cells.size() - 1));
    }
  }
  while (!heaviest.empty()) {
    final_cells.push_back(heaviest.top());
    heaviest.pop();
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
    out.member.insert(out.member.end(), member.begin() + cells[c].begin, member.begin() + cells[c].end);
    std::sort(out.member.begin() + static_cast<std::ptrdiff_t>(first), out.member.end());
  }
  out.begin.push_back(static_cast<std::uint32_t>(out.member.size()));
  return out;
}

}  // namespace octocosm
