// Octocosm's levels of detail as subsamples of the input it was built from.
//
// The level-L sample is what a query at level L returns (docs/QUERIES.md):
// the points of the nodes at level L and of the leaves shallower than L,
// which together cover the data once. Nodes come from a build (AddNode, fed
// by a NodeSink) or from a store (AddStore, read through the block codec), and
// their points are matched to the input by particle ID, so each level is a
// Subsample of the input: indices and the weights octocosm gave them.
#pragma once

#include <cstdint>
#include <map>
#include <unordered_map>
#include <vector>

#include "accuracy/sample_score.h"
#include "index/dataset.h"
#include "index/morton.h"
#include "index/node_points.h"
#include "index/subtree_builder.h"

namespace octocosm::accuracy {

class LevelSamples {
 public:
  // ids[i] is the particle ID of input point i; IDs must be unique
  // (Error::InvalidArgument otherwise).
  explicit LevelSamples(const std::vector<std::uint64_t>& ids);

  // One node, in any order. Its points must carry IDs of input points
  // (Error::InvalidArgument naming the node otherwise).
  void AddNode(NodeKey key, const NodePoints& points);
  // Every node of one epoch of a store (IDs and weights decoded).
  void AddStore(const Dataset& dataset, std::uint32_t epoch);

  // The deepest level holding a node.
  int depth() const;
  Subsample AtLevel(int level) const;
  // The leaf holding each input point, in input order. Throws
  // Error::InvalidArgument when a point is in no leaf or in two.
  std::vector<NodeKey> Leaves() const;

 private:
  bool IsLeaf(NodeKey key) const;

  std::unordered_map<std::uint64_t, std::uint32_t> index_of_;
  std::map<NodeKey, Subsample> nodes_;
};

// The levels of the tree BuildSubtree makes of `points` (which must carry
// IDs) from the root of `cube`.
LevelSamples BuildLevelSamples(const ParticleChunk& points, const Cube& cube, const SubtreeOptions& options);

}  // namespace octocosm::accuracy
