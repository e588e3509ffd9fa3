#include "tools/ingest/chunker.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <optional>
#include <unordered_map>

#include "storage/error.h"

namespace octocosm {
namespace {

// Appends the elements `indices` of `from` to `to`, `width` values per point.
// The target is sized once and written through a pointer: a per-point
// vector::insert was a call per point and column.
template <typename T>
void AppendSelected(const std::vector<T>& from, const std::vector<std::uint32_t>& indices, std::size_t width,
                    std::vector<T>& to) {
  const std::size_t old = to.size();
  to.resize(old + width * indices.size());  // grows geometrically, like push_back
  T* out = to.data() + old;
  const T* in = from.data();
  if (width == 3) {
    for (const std::uint32_t i : indices) {
      out[0] = in[3 * std::size_t{i}];
      out[1] = in[3 * std::size_t{i} + 1];
      out[2] = in[3 * std::size_t{i} + 2];
      out += 3;
    }
  } else {
    for (const std::uint32_t i : indices) *out++ = in[i];
  }
}

// Copies the points `indices` of `from` to the end of `to` (all columns
// `from` carries).
void AppendPoints(const ParticleChunk& from, const std::vector<std::uint32_t>& indices, ParticleChunk& to) {
  AppendSelected(from.position, indices, 3, to.position);
  AppendSelected(from.mass, indices, 1, to.mass);
  AppendSelected(from.type, indices, 1, to.type);
  if (from.has_id()) AppendSelected(from.id, indices, 1, to.id);
  const auto source = VectorColumns(from);
  const auto target = VectorColumns(to);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (!source[v]->empty()) AppendSelected(*source[v], indices, 3, *target[v]);
  }
}

void AppendAll(const ParticleChunk& from, ParticleChunk& to) {
  std::vector<std::uint32_t> everything(from.size());
  std::iota(everything.begin(), everything.end(), 0u);
  AppendPoints(from, everything, to);
}

}  // namespace

ParticleChunk Chunk::TakePoints() {
  if (path.empty()) return std::move(points);
  ParticleChunk all = std::move(points);  // a remainder that never spilled, if any
  ParticleChunk from_file;
  {
    ParticleFileReader reader(path);
    reader.ReadAll(from_file);
  }
  std::remove(path.c_str());
  path.clear();
  if (all.size() == 0) return from_file;
  AppendAll(all, from_file);
  return from_file;
}

int SplitLevelsFor(std::uint64_t points, std::uint64_t target_points) {
  int levels = 1;
  double cells = 8;
  while (levels < 6 && static_cast<double>(points) > cells * static_cast<double>(std::max<std::uint64_t>(target_points, 1))) {
    ++levels;
    cells *= 8;
  }
  return levels;
}

Chunker::Chunker(const Cube& cube, ChunkerOptions options) : cube_(cube), options_(std::move(options)) {
  cube_.Validate();
  if (options_.split_levels < 1 || options_.split_levels > 6) {
    throw Error::InvalidArgument("chunker split_levels must be 1..6, got " + std::to_string(options_.split_levels));
  }
  if (options_.max_chunk_points == 0) throw Error::InvalidArgument("chunker max_chunk_points must be positive");
  if (options_.max_level < 0 || options_.max_level > kMaxLevel) {
    throw Error::InvalidArgument("depth limit must be 0.." + std::to_string(kMaxLevel));
  }
}

std::string Chunker::NewChunkPath() {
  char name[40];
  std::snprintf(name, sizeof name, "/chunk-%06llu.pts", static_cast<unsigned long long>(next_file_++));
  return options_.temp_dir + name;
}

std::vector<Chunk> Chunker::Distribute(NodeKey root, int levels, const PointPass& pass) {
  const int level = root.level() + levels;
  const std::uint64_t first = root.DescendantRange(level).first;
  const std::size_t cells = std::size_t{1} << (3 * levels);
  std::vector<Chunk> chunks(cells);
  std::vector<std::optional<ParticleFileWriter>> writers(cells);  // opened on a chunk's first spill
  std::vector<std::vector<std::uint32_t>> picks(cells);
  const std::size_t bytes_per_point = options_.columns.BytesPerPoint();
  const std::size_t max_buffered = std::max<std::size_t>(options_.memory_bytes / bytes_per_point, 1);
  std::size_t buffered_points = 0;

  auto spill = [&](std::size_t c) {
    Chunk& chunk = chunks[c];
    if (chunk.points.size() == 0) return;
    if (chunk.path.empty()) {
      chunk.path = NewChunkPath();
      writers[c].emplace(chunk.path, options_.columns);
    }
    writers[c]->Append(chunk.points);
    spilled_points_ += chunk.points.size();
    buffered_points -= chunk.points.size();
    chunk.points = ParticleChunk();  // give the memory back
  };

  pass([&](const ParticleChunk& batch) {
    if (batch.size() > UINT32_MAX) throw Error::InvalidArgument("chunker: batch too large");
    for (std::uint32_t i = 0; i < batch.size(); ++i) {
      const NodeKey cell = cube_.LeafKey(&batch.position[3 * i], level);
      const std::uint64_t c = cell.value() - first;
      if (cell.value() < first || c >= cells) {
        throw Error::InvalidArgument("chunker: a point lies outside region " + root.Path());
      }
      picks[c].push_back(i);
    }
    for (std::size_t c = 0; c < cells; ++c) {
      if (picks[c].empty()) continue;
      AppendPoints(batch, picks[c], chunks[c].points);
      chunks[c].point_count += picks[c].size();
      buffered_points += picks[c].size();
      picks[c].clear();
    }
    if (buffered_points > max_buffered) {
      // Spill the fullest buffers first: the most memory back per write call.
      std::vector<std::size_t> order(cells);
      std::iota(order.begin(), order.end(), 0);
      std::sort(order.begin(), order.end(),
                [&](std::size_t a, std::size_t b) { return chunks[a].points.size() > chunks[b].points.size(); });
      for (std::size_t c : order) {
        if (buffered_points <= max_buffered / 2) break;
        spill(c);
      }
    }
  });

  std::vector<Chunk> result;
  for (std::size_t c = 0; c < cells; ++c) {
    if (chunks[c].point_count == 0) continue;
    if (!chunks[c].path.empty()) {
      spill(c);  // a chunk that spilled once goes wholly to its file
      writers[c]->Close();
    }
    chunks[c].key = NodeKey::FromValue(first + c);
    result.push_back(std::move(chunks[c]));
  }
  return result;
}

std::vector<Chunk> Chunker::Split(NodeKey root, const PointPass& pass) {
  std::vector<Chunk> chunks = SplitAt(root, options_.split_levels, pass);
  if (options_.leaf_capacity == 0) return chunks;
  return MergeLeafSubtrees(root, std::move(chunks));
}

std::vector<Chunk> Chunker::MergeLeafSubtrees(NodeKey root, std::vector<Chunk> chunks) {
  // Points under every node between the region and the chunks.
  std::unordered_map<std::uint64_t, std::uint64_t> below;
  for (const Chunk& chunk : chunks) {
    for (int level = root.level(); level < chunk.key.level(); ++level) {
      below[chunk.key.AncestorAt(level).value()] += chunk.point_count;
    }
  }
  std::vector<Chunk> result;
  for (std::size_t i = 0; i < chunks.size();) {
    // The highest node above this chunk that the tree makes a leaf, if any.
    NodeKey leaf;
    for (int level = root.level(); level < chunks[i].key.level(); ++level) {
      const NodeKey ancestor = chunks[i].key.AncestorAt(level);
      if (below.at(ancestor.value()) <= options_.leaf_capacity) {
        leaf = ancestor;
        break;
      }
    }
    if (leaf == NodeKey()) {
      result.push_back(std::move(chunks[i++]));
      continue;
    }
    // Its chunks follow each other: they come in depth-first order.
    Chunk merged;
    merged.key = leaf;
    bool spilled = false;
    for (; i < chunks.size() && leaf.IsAncestorOrSelf(chunks[i].key); ++i) {
      spilled |= !chunks[i].path.empty();
      merged.point_count += chunks[i].point_count;
      AppendAll(chunks[i].TakePoints(), merged.points);
    }
    if (spilled) {  // back to a file: memory was short when its parts spilled
      merged.path = NewChunkPath();
      ParticleFileWriter writer(merged.path, options_.columns);
      writer.Append(merged.points);
      writer.Close();
      merged.points = ParticleChunk();
    }
    result.push_back(std::move(merged));
  }
  return result;
}

std::vector<Chunk> Chunker::SplitAt(NodeKey root, int levels, const PointPass& pass) {
  levels = std::min(levels, options_.max_level - root.level());
  std::vector<Chunk> result;
  for (Chunk& chunk : Distribute(root, std::max(levels, 0), pass)) {
    if (chunk.point_count <= options_.max_chunk_points || chunk.key.level() >= options_.max_level) {
      result.push_back(std::move(chunk));
      continue;
    }
    // Split the oversized chunk again, streaming its own file (or buffer).
    PointPass own_pass = [&chunk](const std::function<void(const ParticleChunk&)>& consume) {
      if (chunk.path.empty()) return consume(chunk.points);
      ParticleFileReader reader(chunk.path);
      ParticleChunk batch;
      while (reader.Next(batch)) consume(batch);
    };
    const int finer = std::clamp(SplitLevelsFor(chunk.point_count, options_.max_chunk_points / 2), 1, 3);
    std::vector<Chunk> parts = SplitAt(chunk.key, finer, own_pass);
    if (!chunk.path.empty()) std::remove(chunk.path.c_str());
    for (Chunk& part : parts) result.push_back(std::move(part));
  }
  return result;
}

}  // namespace octocosm
