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
[[noreturn, gnu::cold, gnu::noinline]] void ThrowOutsideChunk(NodeKey chunk) {
  throw Error::InvalidArgument("chunk gatherer: a point lies outside chunk " + chunk.Path());
}

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
  for (const std::uint32_t i : listed) {
    if (i >= resident.size()) {
      throw Error::InvalidArgument("chunk gatherer: chunk " + chunk.key.Path() + " lists point " + std::to_string(i) +
                                   " of " + std::to_string(resident.size()));
    }
  }
  resident.ForEachListedPosition(listed, [&](std::size_t k, const double* position) {
    const std::uint64_t cell = below.Of(position);
    if (cell == CellsBelow::kOutside) ThrowOutsideChunk(chunk.key);
    target_[k] = static_cast<std::uint32_t>(cell);
    ++cell_begin_[cell + 1];
  });
  for (std::size_t cell = 0; cell < cells; ++cell) cell_begin_[cell + 1] += cell_begin_[cell];
  for (std::size_t k = 0; k < n; ++k) target_[k] = cell_begin_[target_[k]]++;

  resident.CopyPoints(listed, target_, points_);
  return points_;
}

}  // namespace octocosm
