// Out-of-core chunking, after PotreeConverter 2: count the points on a coarse
// grid, merge grid cells into octree nodes ("chunks") that each hold at most
// `max_chunk_points`, then distribute every point into its chunk's file. Each
// chunk is afterwards small enough for its subtree to be built in memory.
//
// A grid cell that alone holds more than max_chunk_points (a dense halo, or
// coincident points) cannot be split by this grid; its chunk is split again
// from its own file, one grid level finer each time, until every chunk fits or
// the depth limit is reached (a chunk at the depth limit is kept whole: its
// points coincide to within the finest cell).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "index/cube.h"
#include "index/morton.h"
#include "index/particle_chunk.h"
#include "tools/ingest/particle_file.h"

namespace octocosm {

// One pass over a point set: calls `consume` for each batch, in order.
using PointPass = std::function<void(const std::function<void(const ParticleChunk&)>& consume)>;

struct Chunk {
  NodeKey key;
  std::string path;  // its particle file
  std::uint64_t point_count = 0;
};

struct ChunkerOptions {
  std::uint64_t max_chunk_points = 10'000'000;
  int grid_bits = 7;                  // counting grid: 2^grid_bits cells per axis below the region
  int max_level = kMaxLevel;          // the tree's depth limit
  std::size_t buffer_bytes = 256u << 20;  // distribution buffers, all chunks together
  std::string temp_dir;               // chunk files are created here
  ParticleColumns columns;            // the optional columns the points carry
};

class Chunker {
 public:
  Chunker(const Cube& cube, ChunkerOptions options);

  // Splits the points of region `root` (every point must lie in it) into
  // chunks. Calls `pass` twice (count, distribute), plus one pass over each
  // oversized chunk's own file per extra split. Returns chunks in depth-first
  // order of their keys; every point is in exactly one chunk file.
  std::vector<Chunk> Split(NodeKey root, const PointPass& pass);

  // Bytes of memory the counting grid and distribution buffers use at most.
  std::size_t PeakMemoryBytes() const;

 private:
  struct Plan {
    std::vector<NodeKey> chunks;                 // depth-first
    std::vector<std::uint64_t> counts;           // per chunk
    std::vector<std::int32_t> chunk_of_cell;     // grid cell (Morton order below root) -> chunk, -1 = empty
    int grid_level = 0;                          // absolute level of the counting grid
  };
  Plan Count(NodeKey root, const PointPass& pass) const;
  std::vector<Chunk> Distribute(NodeKey root, const Plan& plan, const PointPass& pass);
  std::string NewChunkPath();

  Cube cube_;
  ChunkerOptions options_;
  std::uint64_t next_file_ = 0;
};

}  // namespace octocosm
