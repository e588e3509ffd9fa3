#include "index/node_points.h"

#include <utility>

namespace octocosm {
namespace {

template <typename T>
std::vector<T> Gather(const std::vector<T>& column, std::span<const std::uint32_t> order, std::size_t stride) {
  if (column.empty()) return {};
  std::vector<T> out;
  out.reserve(order.size() * stride);
  for (const std::uint32_t i : order) {
    for (std::size_t k = 0; k < stride; ++k) out.push_back(column[i * stride + k]);
  }
  return out;
}

}  // namespace

void OrderByOctant(NodePoints& points, NodeKey key, const Cube& cube) {
  const std::size_t n = points.size();
  const int level = key.level();
  std::vector<std::uint8_t> octant(n);
  std::array<std::uint32_t, 9> offsets{};
  bool sorted = true;
  for (std::size_t i = 0; i < n; ++i) {
    octant[i] = static_cast<std::uint8_t>(cube.ChildOctant(&points.position[3 * i], level));
    ++offsets[octant[i] + 1];
    if (i > 0 && octant[i] < octant[i - 1]) sorted = false;
  }
  for (int o = 0; o < 8; ++o) offsets[o + 1] += offsets[o];
  points.octant_offsets = offsets;
  if (sorted) return;

  // A counting sort through a permutation: stable, and each column moves once.
  std::vector<std::uint32_t> order(n);
  std::array<std::uint32_t, 9> next = offsets;
  for (std::size_t i = 0; i < n; ++i) order[next[octant[i]]++] = static_cast<std::uint32_t>(i);
  points.position = Gather(points.position, order, 3);
  points.weight = Gather(points.weight, order, 1);
  points.smoothing = Gather(points.smoothing, order, 1);
  points.id = Gather(points.id, order, 1);
  points.type = Gather(points.type, order, 1);
  for (std::vector<float>* column : VectorColumns(points)) *column = Gather(*column, order, 3);
  points.velocity_dispersion = Gather(points.velocity_dispersion, order, 1);
  points.shape = Gather(points.shape, order, 6);
  points.refine_bound = Gather(points.refine_bound, order, 3);
  points.grid = Gather(points.grid, order, 1);
  std::vector<std::uint32_t> moved_to(n);
  for (std::size_t k = 0; k < n; ++k) moved_to[order[k]] = static_cast<std::uint32_t>(k);
  for (std::uint32_t& cluster : points.child_cluster) cluster = moved_to[cluster];
}

NodePoints SelectRows(const NodePoints& points, std::span<const std::uint32_t> rows) {
  NodePoints out;
  out.position = Gather(points.position, rows, 3);
  out.weight = Gather(points.weight, rows, 1);
  out.smoothing = Gather(points.smoothing, rows, 1);
  out.id = Gather(points.id, rows, 1);
  out.type = Gather(points.type, rows, 1);
  const auto from = VectorColumns(points);
  const auto to = VectorColumns(out);
  for (std::size_t v = 0; v < from.size(); ++v) *to[v] = Gather(*from[v], rows, 3);
  out.velocity_dispersion = Gather(points.velocity_dispersion, rows, 1);
  out.shape = Gather(points.shape, rows, 6);
  out.refine_bound = Gather(points.refine_bound, rows, 3);
  out.grid = Gather(points.grid, rows, 1);
  std::array<std::uint32_t, 9> offsets{};
  int octant = 0;
  for (const std::uint32_t row : rows) {
    while (octant < 7 && row >= points.octant_offsets[octant + 1]) ++octant;
    ++offsets[octant + 1];
  }
  for (int o = 0; o < 8; ++o) offsets[o + 1] += offsets[o];
  out.octant_offsets = offsets;
  return out;
}

}  // namespace octocosm
