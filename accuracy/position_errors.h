// How far decoded positions are from the input: the quantization of the
// block codec (docs/FORMAT.md §4: within s / 131072 per axis of a node of edge
// s) measured through the real encoder and decoder.
#pragma once

#include <cstddef>
#include <cstdint>

#include "index/cube.h"
#include "index/particle_chunk.h"
#include "index/subtree_builder.h"

namespace octocosm::accuracy {

struct PositionErrors {
  std::size_t points = 0;
  int depth = 0;                // deepest node measured
  double worst = 0;             // largest |decoded - input| over every axis, in input units
  double worst_over_bound = 0;  // largest |decoded - input| / (s / 131072), s the edge of the point's node
};

// `count` random points in one node at `level` (a random cell of `cube`),
// through EncodeBlock and DecodeBlock.
PositionErrors NodePositionErrors(const Cube& cube, int level, std::size_t count, std::uint64_t seed);

// The tree BuildSubtree makes of `points` from the root of `cube`, every leaf
// through EncodeBlock and DecodeBlock: each particle's error in its leaf.
PositionErrors LeafPositionErrors(const ParticleChunk& points, const Cube& cube, const SubtreeOptions& options);

}  // namespace octocosm::accuracy
