// The points of one octree node, in memory: what the subtree builder hands
// to its sink, what EncodeBlock writes and what DecodeBlock returns.
//
// Columns are separate (structure of arrays). Points are ordered by the child
// octant that holds them (Cube::ChildOctant at the node's level), and
// octant_offsets records the ranges: the points of octant o are
// [octant_offsets[o], octant_offsets[o + 1]), octant_offsets[8] == size().
// A renderer that refines a node into some of its children can thus draw the
// parent's points of the other octants only.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "index/cube.h"
#include "index/morton.h"
#include "index/particle_chunk.h"

namespace octocosm {

struct NodePoints {
  std::vector<double> position;        // x,y,z interleaved, 3 * size(); absolute coordinates
  std::vector<double> weight;          // size(); the mass each point stands for; they sum to the subtree mass
  std::vector<double> smoothing;       // size(); smoothing length h, absolute units
  std::vector<std::uint64_t> id;       // size(), or empty
  std::vector<std::uint8_t> type;      // size()
  std::vector<float> velocity;         // the vector columns (VectorColumn, index/particle_chunk.h): 3 * size() or empty
  std::vector<float> displacement;
  std::vector<float> next_velocity;
  std::vector<float> prev_displacement;
  std::vector<float> prev_velocity;
  // size(), or empty: the one-dimensional rms velocity dispersion (>= 0, in
  // velocity units) of the particles each point stands for. Only inner nodes
  // whose points are clusters of a dataset with velocities carry it
  // (index/aggregator.h); a single particle's is 0, so leaves leave it empty.
  std::vector<float> velocity_dispersion;
  // 6 * size(), or empty: each point's blob shape as stored (index/cluster_shape.h
  // codes; round where empty). Only inner nodes whose points are clusters carry it.
  std::vector<std::uint8_t> shape;
  // Only inner nodes whose points are clusters carry these two (empty
  // otherwise; index/block_codec.h, columns child_cluster and refine_bound).
  // One entry per point of the node's children, child octant by octant, each
  // child's points in its order: the index of the point of this node (the
  // cluster) that holds it.
  std::vector<std::uint32_t> child_cluster;
  // 3 * size(): each cluster's R, a, r (the sphere about it that holds the
  // clusters below it, and bounds of their mass times blob variance and of
  // their mass).
  std::vector<float> refine_bound;
  std::array<std::uint32_t, 9> octant_offsets{};
  // Empty, or each point's Cube::FinestGridCoords, kept beside the positions
  // by the octree builder so that sampling and encoding place each point
  // with shifts (index/cube.h). EncodeBlock uses it when present; whoever
  // fills it keeps it equal to the positions' (a decoded block leaves it
  // empty).
  std::vector<GridPoint> grid;

  std::size_t size() const { return weight.size(); }
};

// Reorders `points` (every non-empty column together, stably) so that they
// are grouped by the child octant of `key` that holds them, and fills
// octant_offsets; child_cluster's indices follow their points. Precondition:
// every point lies in `key` (Cube::Holds).
void OrderByOctant(NodePoints& points, NodeKey key, const Cube& cube);

// The points `rows` of `points` (ascending, each < points.size()), every
// non-empty column, with octant_offsets counted from those of `points`: the
// subset keeps the grouping by child octant. It has no child_cluster (the
// children's points would name clusters left out).
NodePoints SelectRows(const NodePoints& points, std::span<const std::uint32_t> rows);

}  // namespace octocosm
