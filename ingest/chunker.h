// Out-of-core chunking: splits a point set into "chunks", octree nodes small
// enough for their subtrees to be built in memory, in ONE pass over the input
// (after PotreeConverter 2, minus its counting pass).
//
// Every point goes to its cell `split_levels` levels below the region; each
// non-empty cell is a chunk. Points wait in per-chunk buffers; while all
// buffers fit in `memory_bytes` they stay in memory (a data set that fits in
// the budget never touches the disk), and when they do not, the fullest are
// appended to the chunks' temporary files. A chunk that ends up with more than
// `max_chunk_points` (a dense halo) is split again the same way from its own
// file or buffer, until every chunk fits or the depth limit is reached (a
// chunk at the depth limit is kept whole: its points coincide to within the
// finest cell).
//
// Chunks are cells of a fixed level, so a node above them may hold few
// points: a sparse corner of the data. The octree makes a node with at most
// `leaf_capacity` points a leaf (index/subtree_builder.h), and a chunk cut
// below such a node would make it an inner node instead, its points stored
// twice and the tree dependent on where the chunks were cut (on the thread
// count and the memory budget). So when the points are distributed, the
// chunks under each highest node holding at most `leaf_capacity` points are
// merged into one chunk for that node.
//
// A point set that fits in memory as a whole is better not copied into
// growing buffers: it is read once into a ResidentEpoch (its columns as
// narrow as their values allow, or mapped from the files:
// ingest/resident_epoch.h) and SplitResident cuts the same chunks as
// lists of indices into it; each chunk is copied out only when it is built
// (ingest/chunk_gatherer.h), into buffers that serve chunk after chunk.
// That saves the buffers' growth and any spilling.
// Its split computes each point's cell ten levels down once, on all
// threads, and every later cut reads a coarser cell as a prefix of that one
// (only a clump denser than a chunk inside one such cell is placed from its
// positions again); each cut is a stable counting sort of the listed points.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "index/cube.h"
#include "index/morton.h"
#include "index/particle_chunk.h"
#include "ingest/particle_file.h"
#include "ingest/resident_epoch.h"

namespace octocosm {

struct Chunk {
  NodeKey key;
  std::uint64_t point_count = 0;
  std::string path;       // its particle file, when it spilled to disk
  ParticleChunk points;   // its points, when they stayed in memory (path empty)
  // Its points as indices into the resident point set, when it came from
  // Chunker::SplitResident (then path and points are empty): a stretch of one
  // list that all chunks of a split share, `resident_lists`, which keeps it
  // alive. Within a cell the points are in input order.
  std::span<const std::uint32_t> resident;
  std::shared_ptr<const std::uint32_t[]> resident_lists;

  // Moves the chunk's points out (reading and deleting its file if it has
  // one); not for resident chunks, whose points stay where they are.
  ParticleChunk TakePoints();
};

struct ChunkerOptions {
  std::uint64_t max_chunk_points = 10'000'000;
  int split_levels = 2;                  // levels below the region at which points are bucketed (1..6)
  int max_level = kMaxLevel;             // the tree's depth limit
  std::uint64_t leaf_capacity = 0;       // the tree's node capacity; 0 = chunks are never merged
  std::size_t memory_bytes = 256u << 20;  // buffers of all chunks together
  std::string temp_dir;                  // spilled chunk files are created here
  int threads = 1;                       // threads placing, gathering and spilling points
  ParticleColumns columns;               // the optional columns the points carry
};

class Chunker {
 public:
  Chunker(const Cube& cube, ChunkerOptions options);

  // Splits the points of region `root` (every point must lie in it) into
  // chunks: one call of `pass`, plus one pass over each oversized chunk. Every
  // point ends in exactly one chunk; chunks come in depth-first key order.
  std::vector<Chunk> Split(NodeKey root, const PointPass& pass);

  // The same chunks for a point set held in memory as a whole (read or
  // mapped into `resident`): chunks that list their points as indices into
  // it, the same chunks with the same points in the same order as Split's.
  // Nothing goes through chunk buffers and nothing spills; memory_bytes is
  // not consulted.
  std::vector<Chunk> SplitResident(NodeKey root, const ResidentEpoch& resident);
  // Resident chunks (SplitResident's) with the end of the list cut finer,
  // so that the build threads finish together: while one of the last
  // `window` chunks (in list order, where a ChunkQueue of that window takes
  // its last chunks from) holds more than `most_points` points and is an
  // inner node of the tree (more than leaf_capacity points, above max_level),
  // the largest such chunk is replaced by its children's chunks, one level
  // down, cut from the positions. The list stays in depth-first order; the
  // tree does not change (the split chunk's root is then sampled above the
  // chunks, as every chunk root's parent is). Why: at 10^7 points in 64
  // chunks the other thread idled for 23 ms on average while the last chunk
  // was built.
  std::vector<Chunk> SplitTail(std::vector<Chunk> chunks, const ResidentEpoch& resident, std::size_t window,
                               std::uint64_t most_points);

  // The memory SplitResident takes per point on top of the resident points:
  // its cell while the split runs, its index in the chunks' shared list (kept
  // until the chunks are built), and for a point in a chunk that is split
  // again, its index in that split's order for a moment.
  static constexpr std::size_t kResidentScratchBytesPerPoint = 4 + 4 + 4;

  std::uint64_t spilled_points() const { return spilled_points_; }
  // The most points chunk buffers held at once during Split: within
  // memory_bytes' worth plus one batch of the pass.
  std::uint64_t peak_buffered_points() const { return peak_buffered_points_; }

 private:
  // Whether a chunk must be split again, and by how many levels.
  bool Oversized(const Chunk& chunk) const;
  int ResplitLevels(std::uint64_t points) const;
  struct ResidentCells;
  std::vector<Chunk> SplitResidentAt(NodeKey root, int levels, const ResidentEpoch& resident,
                                     const ResidentCells& cells, std::span<std::uint32_t> subset,
                                     const std::shared_ptr<std::uint32_t[]>& lists);
  std::vector<Chunk> SplitAt(NodeKey root, int levels, const PointPass& pass);
  std::vector<Chunk> Distribute(NodeKey root, int levels, const PointPass& pass);
  std::vector<Chunk> MergeLeafSubtrees(NodeKey root, std::vector<Chunk> chunks);
  std::string NewChunkPath();
  // Points memory_bytes holds in chunk buffers.
  std::size_t BufferedPointBudget() const;
  // Writes the buffered points of `chunks` (the largest first) to files of
  // their own until held_points_ is at most `target`.
  void SpillHeld(std::vector<Chunk>& chunks, std::uint64_t target);

  Cube cube_;
  ChunkerOptions options_;
  std::uint64_t next_file_ = 0;
  std::uint64_t spilled_points_ = 0;
  // Points in the buffers of chunks Distribute returned, while Split runs:
  // the chunks that later splits of oversized ones must leave room for, so
  // that all buffers together stay within memory_bytes.
  std::uint64_t held_points_ = 0;
  std::uint64_t peak_buffered_points_ = 0;
};

// The number of levels to bucket `points` by so that chunks come out near
// `target_points` each: ceil(log8(points / target_points)), at least 1.
int SplitLevelsFor(std::uint64_t points, std::uint64_t target_points);

}  // namespace octocosm
