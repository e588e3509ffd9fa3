#include "tools/ingest/chunker.h"

#include <algorithm>
#include <cstdio>
#include <numeric>

#include "storage/error.h"

namespace octocosm {
namespace {

// Copies the points `indices` of `from` to the end of `to` (all columns `from` carries).
void AppendPoints(const ParticleChunk& from, const std::vector<std::uint32_t>& indices, ParticleChunk& to) {
  const std::size_t old = to.size();
  const std::size_t n = indices.size();
  to.position.resize(3 * (old + n));
  to.mass.resize(old + n);
  to.type.resize(old + n);
  if (from.has_velocity()) to.velocity.resize(3 * (old + n));
  if (from.has_id()) to.id.resize(old + n);
  if (!from.displacement.empty()) to.displacement.resize(3 * (old + n));
  for (std::size_t j = 0; j < n; ++j) {
    const std::size_t i = indices[j], k = old + j;
    for (int a = 0; a < 3; ++a) to.position[3 * k + a] = from.position[3 * i + a];
    to.mass[k] = from.mass[i];
    to.type[k] = from.type[i];
    if (from.has_velocity()) {
      for (int a = 0; a < 3; ++a) to.velocity[3 * k + a] = from.velocity[3 * i + a];
    }
    if (from.has_id()) to.id[k] = from.id[i];
    if (!from.displacement.empty()) {
      for (int a = 0; a < 3; ++a) to.displacement[3 * k + a] = from.displacement[3 * i + a];
    }
  }
}

}  // namespace

Chunker::Chunker(const Cube& cube, ChunkerOptions options) : cube_(cube), options_(std::move(options)) {
  cube_.Validate();
  if (options_.grid_bits < 1 || options_.grid_bits > 8) {
    throw Error::InvalidArgument("chunker grid_bits must be 1..8, got " + std::to_string(options_.grid_bits));
  }
  if (options_.max_chunk_points == 0) throw Error::InvalidArgument("chunker max_chunk_points must be positive");
  if (options_.max_level < 0 || options_.max_level > kMaxLevel) {
    throw Error::InvalidArgument("depth limit must be 0.." + std::to_string(kMaxLevel));
  }
}

std::size_t Chunker::PeakMemoryBytes() const {
  const std::size_t cells = std::size_t{1} << (3 * options_.grid_bits);
  return cells * (sizeof(std::uint64_t) + sizeof(std::int32_t)) + options_.buffer_bytes;
}

std::string Chunker::NewChunkPath() {
  char name[40];
  std::snprintf(name, sizeof name, "/chunk-%06llu.pts", static_cast<unsigned long long>(next_file_++));
  return options_.temp_dir + name;
}

Chunker::Plan Chunker::Count(NodeKey root, const PointPass& pass) const {
  Plan plan;
  const int bits = std::min(options_.grid_bits, options_.max_level - root.level());
  plan.grid_level = root.level() + bits;
  const std::uint64_t first = root.DescendantRange(plan.grid_level).first;
  std::vector<std::uint64_t> counts(std::size_t{1} << (3 * bits), 0);
  pass([&](const ParticleChunk& chunk) {
    for (std::size_t i = 0; i < chunk.size(); ++i) {
      const NodeKey cell = cube_.LeafKey(&chunk.position[3 * i], plan.grid_level);
      if (!root.IsAncestorOrSelf(cell)) {
        throw Error::InvalidArgument("chunker: a point lies outside region " + root.Path());
      }
      ++counts[cell.value() - first];
    }
  });

  // Sums over aligned groups: the count of a node at depth d below the root
  // is the sum of its 8^(bits-d) grid cells, which are contiguous in Morton order.
  std::vector<std::vector<std::uint64_t>> level_counts(static_cast<std::size_t>(bits) + 1);
  level_counts[static_cast<std::size_t>(bits)] = std::move(counts);
  for (int d = bits - 1; d >= 0; --d) {
    const auto& finer = level_counts[static_cast<std::size_t>(d) + 1];
    auto& coarser = level_counts[static_cast<std::size_t>(d)];
    coarser.assign(finer.size() / 8, 0);
    for (std::size_t i = 0; i < coarser.size(); ++i) {
      coarser[i] = std::accumulate(finer.begin() + static_cast<std::ptrdiff_t>(8 * i),
                                   finer.begin() + static_cast<std::ptrdiff_t>(8 * i + 8), std::uint64_t{0});
    }
  }

  plan.chunk_of_cell.assign(level_counts[static_cast<std::size_t>(bits)].size(), -1);
  // Depth-first: a node small enough (or at the grid's bottom) becomes a chunk.
  auto visit = [&](auto&& self, int d, std::uint64_t index) -> void {
    const std::uint64_t count = level_counts[static_cast<std::size_t>(d)][index];
    if (count == 0) return;
    if (count <= options_.max_chunk_points || d == bits) {
      const auto chunk_index = static_cast<std::int32_t>(plan.chunks.size());
      const NodeKey key = NodeKey::FromValue((root.value() << (3 * d)) | index);
      plan.chunks.push_back(key);
      plan.counts.push_back(count);
      const int shift = 3 * (bits - d);
      std::fill(plan.chunk_of_cell.begin() + static_cast<std::ptrdiff_t>(index << shift),
                plan.chunk_of_cell.begin() + static_cast<std::ptrdiff_t>((index + 1) << shift), chunk_index);
      return;
    }
    for (std::uint64_t octant = 0; octant < 8; ++octant) self(self, d + 1, index * 8 + octant);
  };
  visit(visit, 0, 0);
  return plan;
}

std::vector<Chunk> Chunker::Distribute(NodeKey root, const Plan& plan, const PointPass& pass) {
  const std::uint64_t first = root.DescendantRange(plan.grid_level).first;
  std::vector<Chunk> chunks(plan.chunks.size());
  std::vector<ParticleFileWriter> writers;
  writers.reserve(chunks.size());
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    chunks[c] = {plan.chunks[c], NewChunkPath(), 0};
    writers.emplace_back(chunks[c].path, options_.columns);
  }
  // Points wait in per-chunk buffers; when all buffers together exceed the
  // budget the fullest ones are written out. (An open FILE per chunk with its
  // own buffer would cost chunks x buffer size of memory.)
  std::vector<ParticleChunk> buffers(chunks.size());
  std::vector<std::vector<std::uint32_t>> picks(chunks.size());
  const std::size_t bytes_per_point = options_.columns.BytesPerPoint();
  std::size_t buffered_points = 0;
  const std::size_t max_buffered = std::max<std::size_t>(options_.buffer_bytes / bytes_per_point, 1);

  auto flush = [&](std::size_t c) {
    if (buffers[c].size() == 0) return;
    writers[c].Append(buffers[c]);
    chunks[c].point_count += buffers[c].size();
    buffered_points -= buffers[c].size();
    buffers[c].clear();
  };

  pass([&](const ParticleChunk& batch) {
    if (batch.size() > UINT32_MAX) throw Error::InvalidArgument("chunker: batch too large");
    for (std::uint32_t i = 0; i < batch.size(); ++i) {
      const NodeKey cell = cube_.LeafKey(&batch.position[3 * i], plan.grid_level);
      const std::int32_t c = cell.value() >= first && cell.value() - first < plan.chunk_of_cell.size()
                                 ? plan.chunk_of_cell[cell.value() - first]
                                 : -1;
      if (c < 0) {
        throw Error::InvalidArgument(
            "chunker: the input changed between passes (a point fell into a cell the counting pass found empty)");
      }
      picks[static_cast<std::size_t>(c)].push_back(i);
    }
    for (std::size_t c = 0; c < chunks.size(); ++c) {
      if (picks[c].empty()) continue;
      AppendPoints(batch, picks[c], buffers[c]);
      buffered_points += picks[c].size();
      picks[c].clear();
    }
    if (buffered_points > max_buffered) {
      // Write the fullest half of the buffers, which frees most memory per write call.
      std::vector<std::size_t> order(chunks.size());
      std::iota(order.begin(), order.end(), 0);
      std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return buffers[a].size() > buffers[b].size(); });
      for (std::size_t c : order) {
        if (buffered_points <= max_buffered / 2) break;
        flush(c);
      }
    }
  });
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    flush(c);
    writers[c].Close();
    if (chunks[c].point_count != plan.counts[c]) {
      throw Error::InvalidArgument("chunker: chunk " + chunks[c].key.Path() + " received " +
                                   std::to_string(chunks[c].point_count) + " points but the counting pass found " +
                                   std::to_string(plan.counts[c]) + " (the input changed between passes)");
    }
  }
  return chunks;
}

std::vector<Chunk> Chunker::Split(NodeKey root, const PointPass& pass) {
  const Plan plan = Count(root, pass);
  std::vector<Chunk> distributed = Distribute(root, plan, pass);
  std::vector<Chunk> result;
  for (Chunk& chunk : distributed) {
    const bool oversized = chunk.point_count > options_.max_chunk_points;
    if (!oversized || chunk.key.level() >= options_.max_level) {
      result.push_back(std::move(chunk));
      continue;
    }
    // Split the oversized chunk from its own file, then drop the file.
    const std::string path = chunk.path;
    PointPass file_pass = [&path](const std::function<void(const ParticleChunk&)>& consume) {
      ParticleFileReader reader(path);
      ParticleChunk batch;
      while (reader.Next(batch)) consume(batch);
    };
    std::vector<Chunk> parts = Split(chunk.key, file_pass);
    std::remove(path.c_str());
    for (Chunk& part : parts) result.push_back(std::move(part));
  }
  return result;
}

}  // namespace octocosm
