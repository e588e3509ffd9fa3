// What the ranks of a spread epoch send one another (ingest/rank_group.h):
// particles on their way to the rank whose domain holds them, and the
// domains' root nodes on their way to rank 0. Exact: doubles go as they are.
// Only ranks of one ingest, one build of the program, read them, so the
// layout is private; lengths are still checked, so that a short message is
// an error, not a misread.
#pragma once

#include <cstdint>
#include <span>

#include "index/morton.h"
#include "index/node_points.h"
#include "index/particle_chunk.h"
#include "ingest/particle_file.h"
#include "storage/block_source.h"

namespace octocosm {

// Appends the points `indices` of `points` (which carries `columns`), as
// one segment headed by `tag`.
void AppendPointSegment(std::uint32_t tag, const ParticleChunk& points, std::span<const std::uint32_t> indices,
                        const ParticleColumns& columns, Bytes& out);

// Reads the segments of `message` (AppendPointSegment's) in order, handing
// each to `visit` with its tag. Throws Error::Corruption naming `what` for a
// message cut short.
template <typename Visit>
void ForEachPointSegment(std::span<const std::uint8_t> message, const ParticleColumns& columns, const char* what,
                         Visit&& visit);

Bytes PackNode(NodeKey key, const NodePoints& points);
// Throws Error::Corruption naming `what` for a message of the wrong size.
NodePoints UnpackNode(std::span<const std::uint8_t> message, NodeKey& key, const char* what);

// One segment from `message` at `offset` (advanced past it).
ParticleChunk ReadPointSegment(std::span<const std::uint8_t> message, std::size_t& offset,
                               const ParticleColumns& columns, std::uint32_t& tag, const char* what);

template <typename Visit>
void ForEachPointSegment(std::span<const std::uint8_t> message, const ParticleColumns& columns, const char* what,
                         Visit&& visit) {
  std::size_t offset = 0;
  while (offset < message.size()) {
    std::uint32_t tag = 0;
    ParticleChunk points = ReadPointSegment(message, offset, columns, tag, what);
    visit(tag, points);
  }
}

}  // namespace octocosm
