#include "accuracy/position_errors.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <unordered_map>
#include <unordered_set>

#include "base/error.h"
#include "index/block_codec.h"

namespace octocosm::accuracy {
namespace {

// Adds the errors of `decoded` against `original` (same order) in node `key`.
void Measure(const NodePoints& original, const NodePoints& decoded, NodeKey key, const Cube& cube,
             PositionErrors& errors) {
  const double bound = cube.NodeSize(key.level()) / 131072;
  for (std::size_t i = 0; i < original.position.size(); ++i) {
    const double error = std::fabs(decoded.position[i] - original.position[i]);
    errors.worst = std::max(errors.worst, error);
    errors.worst_over_bound = std::max(errors.worst_over_bound, error / bound);
  }
  errors.points += original.size();
  errors.depth = std::max(errors.depth, key.level());
}

}  // namespace

PositionErrors NodePositionErrors(const Cube& cube, int level, std::size_t count, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  const auto cells = std::uint32_t{1} << level;
  const NodeKey key = NodeKey::FromCell(level, {static_cast<std::uint32_t>(rng() % cells),
                                                static_cast<std::uint32_t>(rng() % cells),
                                                static_cast<std::uint32_t>(rng() % cells)});
  const NodeCube node = cube.NodeCubeOf(key);
  NodePoints points;
  while (points.size() < count) {
    double x[3];
    for (int a = 0; a < 3; ++a) x[a] = node.origin[a] + unit(rng) * node.size;
    if (!cube.Holds(key, x)) continue;  // rounded onto the next node's face
    points.position.insert(points.position.end(), x, x + 3);
    points.weight.push_back(1);
    points.smoothing.push_back(node.size / 16);
    points.type.push_back(0);
  }
  OrderByOctant(points, key, cube);
  const NodePoints decoded = DecodeBlock(EncodeBlock(points, key, cube), kAllColumns, key, cube, "probe").points;
  PositionErrors errors;
  Measure(points, decoded, key, cube, errors);
  return errors;
}

PositionErrors LeafPositionErrors(const ParticleChunk& points, const Cube& cube, const SubtreeOptions& options) {
  // The sink sees children before their parent: a node is a leaf when none
  // of its children came before it.
  std::unordered_set<std::uint64_t> emitted;
  std::unordered_map<std::uint64_t, NodePoints> nodes;  // the leaves
  ParticleChunk work = points;
  BuildSubtree(work, NodeKey::Root(), cube, options, [&](NodeKey key, const NodePoints& node) {
    bool leaf = true;
    for (int o = 0; o < 8 && key.level() < kMaxLevel; ++o) leaf &= !emitted.count(key.Child(o).value());
    emitted.insert(key.value());
    if (leaf) nodes[key.value()] = node;
  });
  PositionErrors errors;
  for (const auto& [value, node] : nodes) {
    const NodeKey key = NodeKey::FromValue(value);
    const NodePoints decoded = DecodeBlock(EncodeBlock(node, key, cube), kAllColumns, key, cube, "probe").points;
    Measure(node, decoded, key, cube, errors);
  }
  return errors;
}

}  // namespace octocosm::accuracy
