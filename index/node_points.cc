#include "index/node_points.h"

#include <utility>

namespace octocosm {
namespace {

template <typename T>
std::vector<T> Gather(const std::vector<T>& column, const std::vector<std::uint32_t>& order, std::size_t stride) {
  if (column.empty()) return {};
  std::vector<T> out;
  out.reserve(column.size());
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
  points.grid = Gather(points.grid, order, 1);
}

}  // namespace octocosm
