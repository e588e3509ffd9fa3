#include "accuracy/level_samples.h"

#include <algorithm>
#include <string>

#include "base/error.h"
#include "index/block_codec.h"

namespace octocosm::accuracy {

LevelSamples::LevelSamples(const std::vector<std::uint64_t>& ids) {
  index_of_.reserve(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (!index_of_.emplace(ids[i], static_cast<std::uint32_t>(i)).second) {
      throw Error::InvalidArgument("LevelSamples: particle ID " + std::to_string(ids[i]) + " appears twice");
    }
  }
}

void LevelSamples::AddNode(NodeKey key, const NodePoints& points) {
  if (points.id.size() != points.size()) {
    throw Error::InvalidArgument("LevelSamples: node " + key.Path() + " carries no particle IDs");
  }
  Subsample& node = nodes_[key];
  node.index.clear();
  node.weight = points.weight;
  for (const std::uint64_t id : points.id) {
    const auto it = index_of_.find(id);
    if (it == index_of_.end()) {
      throw Error::InvalidArgument("LevelSamples: node " + key.Path() + " holds particle ID " + std::to_string(id) +
                                   ", which the input does not");
    }
    node.index.push_back(it->second);
  }
}

void LevelSamples::AddStore(const Dataset& dataset, std::uint32_t epoch) {
  std::vector<std::uint64_t> keys;
  dataset.store().Scan(epoch, 0, ~std::uint64_t{0}, [&](const IndexEntry& entry) {
    keys.push_back(entry.key);
    return true;
  });
  for (const std::uint64_t k : keys) {
    const NodeKey key = NodeKey::FromValue(k);
    const Bytes bytes = dataset.store().ReadBlock({epoch, k});
    const DecodedBlock block = DecodeBlock(bytes, ColumnBit(ColumnId::kId) | ColumnBit(ColumnId::kWeight), key,
                                           dataset.cube(epoch), dataset.Where(epoch, key));
    AddNode(key, block.points);
  }
}

int LevelSamples::depth() const {
  int depth = 0;
  for (const auto& [key, node] : nodes_) depth = std::max(depth, key.level());
  return depth;
}

bool LevelSamples::IsLeaf(NodeKey key) const {
  if (key.level() == kMaxLevel) return true;
  // The children of a node are the keys (key << 3) | 0..7: one range.
  const auto child = nodes_.lower_bound(key.Child(0));
  return child == nodes_.end() || child->first > key.Child(7);
}

Subsample LevelSamples::AtLevel(int level) const {
  Subsample sample;
  for (const auto& [key, node] : nodes_) {
    if (key.level() == level || (key.level() < level && IsLeaf(key))) {
      sample.index.insert(sample.index.end(), node.index.begin(), node.index.end());
      sample.weight.insert(sample.weight.end(), node.weight.begin(), node.weight.end());
    }
  }
  return sample;
}

std::vector<NodeKey> LevelSamples::Leaves() const {
  std::vector<NodeKey> leaf(index_of_.size());
  for (const auto& [key, node] : nodes_) {
    if (!IsLeaf(key)) continue;
    for (const std::uint32_t i : node.index) {
      if (leaf[i] != NodeKey()) {
        throw Error::InvalidArgument("LevelSamples: point " + std::to_string(i) + " is in leaves " + leaf[i].Path() +
                                     " and " + key.Path());
      }
      leaf[i] = key;
    }
  }
  for (std::size_t i = 0; i < leaf.size(); ++i) {
    if (leaf[i] == NodeKey()) throw Error::InvalidArgument("LevelSamples: point " + std::to_string(i) + " is in no leaf");
  }
  return leaf;
}

LevelSamples BuildLevelSamples(const ParticleChunk& points, const Cube& cube, const SubtreeOptions& options) {
  LevelSamples levels(points.id);
  ParticleChunk work = points;  // BuildSubtree reorders its input
  BuildSubtree(work, NodeKey::Root(), cube, options,
               [&](NodeKey key, const NodePoints& node) { levels.AddNode(key, node); });
  return levels;
}

}  // namespace octocosm::accuracy
