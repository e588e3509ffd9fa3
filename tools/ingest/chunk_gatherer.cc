#include "tools/ingest/chunk_gatherer.h"

#include <cstddef>
#include <string>

#include "index/cells_below.h"
#include "storage/error.h"

namespace octocosm {
namespace {

// Cells of about this many points, at most this many levels below the chunk
// (8^6 cells).
constexpr std::size_t kPointsPerOrderingCell = 16;
constexpr int kMaxOrderingDepth = 6;
// The listed points lie scattered across the resident columns, so each read
// of one is a cache miss; fetching this many points ahead lets the misses
// overlap instead of queueing one behind another.
constexpr std::size_t kPrefetchDistance = 16;

}  // namespace

void ChunkGatherer::Reserve(const ResidentEpoch& resident, std::size_t points) {
  target_.reserve(points);
  points_.position.reserve(3 * points);
  points_.mass.reserve(points);
  points_.type.reserve(points);
  if (resident.columns().id) points_.id.reserve(points);
  const auto to = VectorColumns(points_);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (resident.columns().vectors[v]) to[v]->reserve(3 * points);
  }
}

const ParticleChunk& ChunkGatherer::Gather(const ResidentEpoch& resident, const Chunk& chunk) {
  const std::span<const std::uint32_t> listed = chunk.resident;
  const std::size_t n = listed.size();
  int depth = 0;
  while (depth < kMaxOrderingDepth && chunk.key.level() + depth < max_level_ &&
         (std::uint64_t{kPointsPerOrderingCell} << (3 * depth)) < n) {
    ++depth;
  }
  const CellsBelow below(cube_, chunk.key, chunk.key.level() + depth);
  const std::size_t cells = below.count();

  // Each point's cell, counted; then, cell by cell in Morton order, its slot.
  target_.resize(n);
  cell_begin_.assign(cells + 1, 0);
  const std::size_t resident_points = resident.size();
  for (std::size_t k = 0; k < n; ++k) {
    if (k + kPrefetchDistance < n && listed[k + kPrefetchDistance] < resident_points) {
      __builtin_prefetch(resident.PositionAddress(listed[k + kPrefetchDistance]));
    }
    if (listed[k] >= resident_points) {
      throw Error::InvalidArgument("chunk gatherer: chunk " + chunk.key.Path() + " lists point " +
                                   std::to_string(listed[k]) + " of " + std::to_string(resident_points));
    }
    const std::uint64_t cell = below.Of(resident.Position(listed[k]).data());
    if (cell == CellsBelow::kOutside) throw Error::InvalidArgument("chunk gatherer: a point lies outside chunk " + chunk.key.Path());
    target_[k] = static_cast<std::uint32_t>(cell);
    ++cell_begin_[cell + 1];
  }
  for (std::size_t cell = 0; cell < cells; ++cell) cell_begin_[cell + 1] += cell_begin_[cell];
  for (std::size_t k = 0; k < n; ++k) target_[k] = cell_begin_[target_[k]]++;

  resident.CopyPoints(listed, target_, points_);
  return points_;
}

}  // namespace octocosm
