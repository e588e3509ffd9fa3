#include "tools/ingest/chunk_gatherer.h"

#include <cstddef>
#include <string>

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

// to[target[k]] = from[listed[k]], `width` values a point; `to` is sized to
// the listed points, or left empty with `from`.
template <typename T>
void GatherColumn(const std::vector<T>& from, std::span<const std::uint32_t> listed,
                  const std::vector<std::uint32_t>& target, std::size_t width, std::vector<T>& to) {
  if (from.empty()) {
    to.clear();
    return;
  }
  to.resize(width * listed.size());
  T* out = to.data();
  const T* in = from.data();
  for (std::size_t k = 0; k < listed.size(); ++k) {
    if (k + kPrefetchDistance < listed.size()) __builtin_prefetch(&in[width * listed[k + kPrefetchDistance]]);
    const std::size_t i = width * std::size_t{listed[k]};
    const std::size_t j = width * std::size_t{target[k]};
    for (std::size_t a = 0; a < width; ++a) out[j + a] = in[i + a];
  }
}

}  // namespace

void ChunkGatherer::Reserve(const ParticleChunk& resident, std::size_t points) {
  target_.reserve(points);
  const auto reserve = [points](const auto& from, std::size_t width, auto& to) {
    if (!from.empty()) to.reserve(width * points);
  };
  reserve(resident.position, 3, points_.position);
  reserve(resident.mass, 1, points_.mass);
  reserve(resident.type, 1, points_.type);
  reserve(resident.id, 1, points_.id);
  const auto from = VectorColumns(resident);
  const auto to = VectorColumns(points_);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) reserve(*from[v], 3, *to[v]);
}

const ParticleChunk& ChunkGatherer::Gather(const ParticleChunk& resident, const Chunk& chunk) {
  const std::span<const std::uint32_t> listed = chunk.resident;
  const std::size_t n = listed.size();
  int depth = 0;
  while (depth < kMaxOrderingDepth && chunk.key.level() + depth < max_level_ &&
         (std::uint64_t{kPointsPerOrderingCell} << (3 * depth)) < n) {
    ++depth;
  }
  const int level = chunk.key.level() + depth;
  const std::uint64_t first_cell = chunk.key.DescendantRange(level).first;
  const std::size_t cells = std::size_t{1} << (3 * depth);

  // Each point's cell, counted; then, cell by cell in Morton order, its slot.
  target_.resize(n);
  cell_begin_.assign(cells + 1, 0);
  const std::size_t resident_points = resident.size();
  for (std::size_t k = 0; k < n; ++k) {
    if (k + kPrefetchDistance < n && listed[k + kPrefetchDistance] < resident_points) {
      __builtin_prefetch(&resident.position[3 * std::size_t{listed[k + kPrefetchDistance]}]);
    }
    if (listed[k] >= resident_points) {
      throw Error::InvalidArgument("chunk gatherer: chunk " + chunk.key.Path() + " lists point " +
                                   std::to_string(listed[k]) + " of " + std::to_string(resident_points));
    }
    const std::uint64_t cell = cube_.LeafKey(&resident.position[3 * std::size_t{listed[k]}], level).value() - first_cell;
    if (cell >= cells) throw Error::InvalidArgument("chunk gatherer: a point lies outside chunk " + chunk.key.Path());
    target_[k] = static_cast<std::uint32_t>(cell);
    ++cell_begin_[cell + 1];
  }
  for (std::size_t cell = 0; cell < cells; ++cell) cell_begin_[cell + 1] += cell_begin_[cell];
  for (std::size_t k = 0; k < n; ++k) target_[k] = cell_begin_[target_[k]]++;

  GatherColumn(resident.position, listed, target_, 3, points_.position);
  GatherColumn(resident.mass, listed, target_, 1, points_.mass);
  GatherColumn(resident.type, listed, target_, 1, points_.type);
  GatherColumn(resident.id, listed, target_, 1, points_.id);
  const auto from = VectorColumns(resident);
  const auto to = VectorColumns(points_);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) GatherColumn(*from[v], listed, target_, 3, *to[v]);
  return points_;
}

}  // namespace octocosm
