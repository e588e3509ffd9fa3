// In-memory, bottom-up construction of the octree below one region, and of
// the levels above a set of such regions.
//
// BuildSubtree takes the particles of one region (a node key; the chunks of
// the out-of-core pipeline) and builds its subtree:
//  - a node with at most `capacity` particles, or at max_level, is a leaf and
//    keeps all of them, each with weight = its mass;
//  - any other node is split into its eight octants (empty octants get no
//    node), the children are built first, and the node's population is the
//    union of its children's kept points with their weights, sampled down to
//    `capacity` points by SampleNode (index/sampler.h).
// So every particle ends in exactly one leaf, every node holds at most
// `capacity` points except a leaf at max_level (particles that still
// coincide there stay together: the one documented exception), and the
// weights of every node sum to the mass of its subtree.
//
// A leaf's points get their smoothing lengths by the density-grid rule
// (index/sampler.h, step 5: LeafSmoothingLengths), except where the
// particles carry given ones (ParticleChunk::smoothing, e.g. a snapshot's
// own): a particle whose given length is > 0 keeps it, held to the range a
// block can store (GivenSmoothingRange: the codec writes h as a 16-bit log2
// code relative to the node's size s, from s * 2^-24 to just below
// s * 2^8, docs/FORMAT.md), and one with 0 gets the grid rule's, computed
// over all the leaf's points as without given lengths. Inner nodes' points
// get the sampler's lengths either way: a kept point stands for more mass
// than its particle, and its length must cover that.
//
// Each node is handed to `sink` as soon as it is complete, children before
// their parent (post-order), with its points ordered by child octant and
// octant_offsets filled (ready for EncodeBlock). The sink is called on the
// calling thread only, so it needs no locking of its own; distinct calls of
// BuildSubtree share nothing and may run on different threads.
//
// Each particle is placed once on the finest grid (index/cube.h,
// GridPoint); every later placement is a shift of it. Levels are split by
// partitioning 32-byte records of (grid point, index) in place, octant by
// octant (an American-flag sort one level per recursion step); the
// particles' columns are read once, when a leaf gathers them.
//
// Memory: 32 bytes per particle for the records, one byte per particle of
// the node being split, the finished children of each node on the current
// path (at most 8 * capacity points per level), and about 9 * capacity
// points more while one node is being sampled.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "index/cube.h"
#include "index/morton.h"
#include "index/node_points.h"
#include "index/particle_chunk.h"
#include "index/sampler.h"

namespace octocosm {

// What an inner node holds: clusters of the points below it, each one point
// with their mass, centre of mass and spread (index/aggregator.h), or a
// random subselection of them with mass-conserving weights
// (index/sampler.h). A node whose capacity is below 8 x its particle types
// samples (clusters need one per octant and type).
enum class CoarsePoints { kClusters, kSample };

struct SubtreeOptions {
  std::size_t capacity = 16000;  // most points per node (>= 1)
  int max_level = kMaxLevel;     // deepest level; leaves there may exceed capacity
  CoarsePoints coarse = CoarsePoints::kClusters;
  SamplerOptions sampler;
};

// Receives each finished node; the points are valid during the call only
// (copy what must outlive it).
using NodeSink = std::function<void(NodeKey, const NodePoints&)>;

// Where a particle goes in the build: its grid point (index/cube.h),
// computed once, and its index in the input. Levels are split by reordering
// these 32-byte records, never the particles' columns, and every placement
// below (octants, quantized positions, density cells) is a shift of `grid`.
struct PlacedParticle {
  GridPoint grid;
  std::uint32_t index;
};

// Memory that one thread's BuildSubtree calls reuse, chunk after chunk: the
// placement records (32 bytes a particle) and the octant partition's
// scratch (one byte). Taken fresh at every call instead, they are pages the
// kernel must zero each time. Holds nothing between calls; one per thread.
struct SubtreeWorkspace {
  std::vector<PlacedParticle> placed;
  std::vector<std::uint8_t> octant;
};

// Builds the subtree of `region` from `particles`, which must all lie in the
// region (Cube::Holds) with finite positions, finite masses > 0 and, when
// given, smoothing lengths finite and >= 0; the optional columns present in
// `particles` (id and the vector columns) are carried into every node: a
// kept point keeps its particle's values. Given smoothing lengths go to the
// leaves (above). The particles are left as they are. Returns the region's own node (the same
// points the sink received for it, without child_cluster, which only its
// block needs), for BuildTopLevels; an empty input
// returns an empty node and calls no sink. Throws Error::InvalidArgument on
// input that breaks these rules (naming the first offending particle) or on
// bad options.
// `workspace`, when given, lends its memory to the call.
NodePoints BuildSubtree(const ParticleChunk& particles, NodeKey region, const Cube& cube,
                        const SubtreeOptions& options, const NodeSink& sink, SubtreeWorkspace* workspace = nullptr);

// The smoothing lengths a leaf of edge `node_size` keeps of given ones:
// [node_size * 2^-24, node_size * 2^(-24 + 65535 / 2048)], the least and
// the largest length the block codec stores relative to that node size
// (kSmoothingLog2Min, kSmoothingPerOctave in index/block_codec.h). A given
// length outside it is clamped to it; one inside comes back from a block
// as given, to the codec's relative precision (1.7e-4).
std::pair<double, double> GivenSmoothingRange(double node_size);

struct RegionRoot {
  NodeKey key;
  NodePoints points;  // as returned by BuildSubtree
};

// Builds the nodes above a set of disjoint regions (no key an ancestor of
// another), up to the root: each parent's population is the union of its
// children's points, sampled as in BuildSubtree. Passes each new node to
// `sink`, deepest first, but not the regions themselves (BuildSubtree did).
// Returns the root node (the only region's node when that region is the
// root; empty when there are no points at all). Throws
// Error::InvalidArgument when regions overlap or repeat.
// The same, streaming: regions arrive one at a time in depth-first order
// (PreorderLess), and each ancestor is sampled and passed to the sink as soon
// as the input has left its subtree, so memory holds at most eight child
// samples per level instead of every region's. This is how an out-of-core
// build merges its chunks. Not thread-safe.
class TopLevelMerger {
 public:
  TopLevelMerger(const Cube& cube, const SubtreeOptions& options, NodeSink sink);
  // Throws Error::InvalidArgument when `region` does not follow the previous
  // one in depth-first order or overlaps it.
  void Add(NodeKey region, NodePoints points);
  // Closes every open ancestor up to the root and returns the root node
  // (empty when there were no points).
  NodePoints Finish();

 private:
  struct Open {
    NodeKey key;
    std::array<NodePoints, 8> children;
  };
  void CloseDeepest();

  Cube cube_;
  SubtreeOptions options_;
  NodeSink sink_;
  std::vector<Open> open_;  // the chain of open ancestors, root first
  NodePoints root_;
  NodeKey last_;
  bool have_last_ = false;
  bool finished_ = false;
};

NodePoints BuildTopLevels(std::vector<RegionRoot> regions, const Cube& cube, const SubtreeOptions& options,
                          const NodeSink& sink);

}  // namespace octocosm
