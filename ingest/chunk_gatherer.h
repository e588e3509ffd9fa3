// Copies a resident chunk's points (Chunker::SplitResident lists them as
// indices into the epoch held in memory whole) into one contiguous
// ParticleChunk for the tree builder, ordered so that each leaf's points lie
// together: in the Morton order of cells a few levels below the chunk, about
// 16 points to a cell and at most 6 levels down (cells found with a product,
// not a division: a point within rounding of a cell face may sit with the
// cell beside it). The tree does not depend on the order of a chunk's
// points, but the build's speed does: a leaf copies its points' columns, and
// when they lie in one stretch that fits the cache, nearly every read hits
// it.
//
// Why a copy per chunk instead of reordering the resident epoch once, chunk
// by chunk: that reordering needed a scratch buffer as large as the widest
// column (24 bytes a point) in fresh memory, whose first touch on the virtual
// machines this runs on cost more than the reordering's copies (at 10^8
// points, 8.8 % of the ingest's CPU against about 5 %), plus a copy of every
// column back; a gatherer's buffers hold one chunk and are reused for the
// next, and the copy runs on the build's threads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "index/cube.h"
#include "index/particle_chunk.h"
#include "ingest/chunker.h"
#include "ingest/resident_epoch.h"

namespace octocosm {

// One per build thread: its buffers serve chunk after chunk.
class ChunkGatherer {
 public:
  // `max_level` is the tree's depth limit: the ordering cells stop there.
  ChunkGatherer(const Cube& cube, int max_level) : cube_(cube), max_level_(max_level) {}

  // The points `chunk.resident` lists, every column `resident` carries, in
  // the order above; valid until the next call. Throws Error::InvalidArgument
  // when an index lies past the resident set. A point outside the chunk is
  // copied like the others: the builder refuses it (BuildSubtree checks
  // every point against its region).
  const ParticleChunk& Gather(const ResidentEpoch& resident, const Chunk& chunk);

  // Sizes the buffers once for chunks of up to `points` points of
  // `resident`'s columns: grown chunk by chunk instead, each growth takes
  // fresh pages and copies what the buffer held.
  void Reserve(const ResidentEpoch& resident, std::size_t points);

 private:
  Cube cube_;
  int max_level_;
  ParticleChunk points_;
  std::vector<std::uint32_t> target_;      // where each listed point goes in points_
  std::vector<std::uint32_t> cell_begin_;  // per ordering cell, its next free slot
};

}  // namespace octocosm
