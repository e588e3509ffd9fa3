#include "render/gpu_block_arena.h"

#include <algorithm>
#include <numeric>
#include <optional>
#include <string>

#include "base/error.h"

namespace octocosm {
namespace {

// Attribute locations of shaders/splat_vert.glsl.
enum Attribute : GLuint {
  kPositionAttribute = 0,
  kWeightAttribute,
  kSmoothingAttribute,
  kTypeAttribute,
  kVelocityAttribute,
  kIdAttribute,
  kDisplacementAttribute,
  kNextVelocityAttribute,
  kPrevDisplacementAttribute,
  kPrevVelocityAttribute,
  kVelocityDispersionAttribute,
  kShapeDiagonalAttribute,
  kShapeOffDiagonalAttribute,
  kDrawIndexAttribute,
  kOwnBoundAttribute,
  kParentClusterAttribute,
};
constexpr GLuint kDrawIndexBinding = 15;

// How a column is read as a vertex attribute.
struct AttributeFormat {
  GLuint location;
  GLint components;
  GLenum type;
  bool integer;     // glVertexArrayAttribIFormat (uint in the shader) or float
  GLuint offset;    // within a point's bytes
};

// A column's bytes per point and its attributes. The id column reads whole
// u64 IDs (two words, low first) or u32 offsets (the high word reads as 0),
// which the shader adds to the block's base; a shape is six byte codes read
// as two triples.
struct ColumnFormat {
  GLsizei stride = 0;
  std::vector<AttributeFormat> attributes;
};

ColumnFormat FormatOf(ColumnId id, bool id_offsets) {
  switch (id) {
    case ColumnId::kPosition: return {6, {{kPositionAttribute, 3, GL_UNSIGNED_SHORT, false, 0}}};
    case ColumnId::kWeight: return {4, {{kWeightAttribute, 1, GL_UNSIGNED_INT, true, 0}}};
    case ColumnId::kSmoothing: return {2, {{kSmoothingAttribute, 1, GL_UNSIGNED_SHORT, false, 0}}};
    case ColumnId::kType: return {1, {{kTypeAttribute, 1, GL_UNSIGNED_BYTE, true, 0}}};
    case ColumnId::kVelocity: return {6, {{kVelocityAttribute, 3, GL_UNSIGNED_SHORT, false, 0}}};
    case ColumnId::kId:
      return id_offsets ? ColumnFormat{4, {{kIdAttribute, 1, GL_UNSIGNED_INT, true, 0}}}
                        : ColumnFormat{8, {{kIdAttribute, 2, GL_UNSIGNED_INT, true, 0}}};
    case ColumnId::kDisplacement: return {6, {{kDisplacementAttribute, 3, GL_UNSIGNED_SHORT, false, 0}}};
    case ColumnId::kNextVelocity: return {6, {{kNextVelocityAttribute, 3, GL_UNSIGNED_SHORT, false, 0}}};
    case ColumnId::kPrevDisplacement: return {6, {{kPrevDisplacementAttribute, 3, GL_UNSIGNED_SHORT, false, 0}}};
    case ColumnId::kPrevVelocity: return {6, {{kPrevVelocityAttribute, 3, GL_UNSIGNED_SHORT, false, 0}}};
    case ColumnId::kVelocityDispersion: return {2, {{kVelocityDispersionAttribute, 1, GL_UNSIGNED_SHORT, false, 0}}};
    case ColumnId::kShape:
      return {6, {{kShapeDiagonalAttribute, 3, GL_UNSIGNED_BYTE, false, 0},
                  {kShapeOffDiagonalAttribute, 3, GL_UNSIGNED_BYTE, false, 3}}};
    case ColumnId::kRefineBound:  // the cut's entries (render/cluster_links.h), not the stored column
      return {20, {{kOwnBoundAttribute, 3, GL_UNSIGNED_SHORT, false, 0},
                   {kParentClusterAttribute, 3, GL_UNSIGNED_INT, true, 8}}};
    case ColumnId::kChildCluster: return {};  // never on the GPU (render/gpu_block.h)
  }
  return {};
}

// A pool's key: its columns, and whether its IDs are u32 offsets.
constexpr std::uint64_t kIdOffsetsBit = std::uint64_t{1} << 40;
std::uint64_t LayoutKey(std::span<const GpuColumnBytes> columns) {
  std::uint64_t key = 0;
  for (const GpuColumnBytes& c : columns) {
    key |= ColumnBit(c.id);
    if (c.id == ColumnId::kId && c.encoding == kEncodingIdOffsets) key |= kIdOffsetsBit;
  }
  return key;
}

constexpr std::uint32_t kFirstPoolPoints = 1u << 16;
constexpr std::uint32_t kFirstSlots = 64;

}  // namespace

struct GpuBlockArena::Pool {
  std::uint64_t key = 0;
  struct Lane {
    ColumnId id;
    ColumnFormat format;
    GlBuffer buffer;
  };
  std::vector<Lane> lanes;
  GlVertexArray vertex_array;
  std::uint32_t capacity = 0;                  // points
  std::map<std::uint32_t, std::uint32_t> free;  // first point -> count, disjoint, not adjacent
};

// Staging for uploads: a quarter of it holds a frame's typical arrivals (a
// few blocks of 16000 points).
constexpr std::size_t kUploadRingBytes = std::size_t{32} << 20;

GpuBlockArena::GpuBlockArena() : uploads_(kUploadRingBytes) { ReserveDrawIndices(1024); }

GpuBlockArena::~GpuBlockArena() = default;

GLuint GpuBlockArena::vertex_array(std::uint32_t pool) const { return pools_.at(pool)->vertex_array.get(); }

std::vector<GpuBlockArena::ColumnBuffer> GpuBlockArena::column_buffers(std::uint32_t pool) const {
  std::vector<ColumnBuffer> columns;
  for (const Pool::Lane& lane : pools_.at(pool)->lanes) {
    columns.push_back({lane.id, lane.buffer.get(), static_cast<std::uint32_t>(lane.format.stride)});
  }
  return columns;
}

std::uint32_t GpuBlockArena::capacity(std::uint32_t pool) const { return pools_.at(pool)->capacity; }

bool GpuBlockArena::id_offsets(std::uint32_t pool) const { return (pools_.at(pool)->key & kIdOffsetsBit) != 0; }

std::size_t GpuBlockArena::gpu_bytes() const {
  std::size_t bytes = std::size_t{slot_capacity_} * sizeof(GpuBlockParameters) + draw_index_capacity_ * 4;
  for (const auto& pool : pools_) {
    for (const Pool::Lane& lane : pool->lanes) bytes += std::size_t{pool->capacity} * static_cast<std::size_t>(lane.format.stride);
  }
  return bytes;
}

void GpuBlockArena::ReserveDrawIndices(std::size_t draws) {
  if (draws <= draw_index_capacity_) return;
  const std::size_t capacity = std::max(draws, 2 * draw_index_capacity_);
  std::vector<std::uint32_t> indices(capacity);
  std::iota(indices.begin(), indices.end(), 0u);
  draw_indices_ = MakeGlBuffer(capacity * 4, indices.data(), 0);
  draw_index_capacity_ = capacity;
  for (const auto& pool : pools_) {
    glVertexArrayVertexBuffer(pool->vertex_array.get(), kDrawIndexBinding, draw_indices_.get(), 0, 4);
  }
  CheckGlError("allocating the draw indices");
}

std::uint32_t GpuBlockArena::PoolFor(std::span<const GpuColumnBytes> columns) {
  const std::uint64_t key = LayoutKey(columns);
  for (std::uint32_t p = 0; p < pools_.size(); ++p) {
    if (pools_[p]->key == key) return p;
  }
  auto pool = std::make_unique<Pool>();
  pool->key = key;
  for (const GpuColumnBytes& c : columns) {
    pool->lanes.push_back({c.id, FormatOf(c.id, c.encoding == kEncodingIdOffsets), GlBuffer()});
  }
  pools_.push_back(std::move(pool));
  return static_cast<std::uint32_t>(pools_.size() - 1);
}

void GpuBlockArena::BuildVertexArray(Pool& pool) {
  GLuint vao = 0;
  glCreateVertexArrays(1, &vao);
  pool.vertex_array = GlVertexArray(vao);
  GLuint binding = 0;
  for (const Pool::Lane& lane : pool.lanes) {
    glVertexArrayVertexBuffer(vao, binding, lane.buffer.get(), 0, lane.format.stride);
    for (const AttributeFormat& f : lane.format.attributes) {
      if (f.integer) {
        glVertexArrayAttribIFormat(vao, f.location, f.components, f.type, f.offset);
      } else {
        glVertexArrayAttribFormat(vao, f.location, f.components, f.type, GL_FALSE, f.offset);
      }
      glVertexArrayAttribBinding(vao, f.location, binding);
      glEnableVertexArrayAttrib(vao, f.location);
    }
    ++binding;
  }
  glVertexArrayVertexBuffer(vao, kDrawIndexBinding, draw_indices_.get(), 0, 4);
  glVertexArrayBindingDivisor(vao, kDrawIndexBinding, 1);
  glVertexArrayAttribIFormat(vao, kDrawIndexAttribute, 1, GL_UNSIGNED_INT, 0);
  glVertexArrayAttribBinding(vao, kDrawIndexAttribute, kDrawIndexBinding);
  glEnableVertexArrayAttrib(vao, kDrawIndexAttribute);
}

void GpuBlockArena::Grow(Pool& pool, std::uint32_t at_least) {
  const std::uint64_t wanted = std::max<std::uint64_t>({kFirstPoolPoints, 2ull * pool.capacity,
                                                       std::uint64_t{pool.capacity} + at_least});
  if (wanted > 0xFFFFFFFFull) throw Error::NotSupported("OpenGL", "more than 2^32 points of one layout on the GPU");
  const std::uint32_t capacity = static_cast<std::uint32_t>(wanted);
  for (Pool::Lane& lane : pool.lanes) {
    GlBuffer grown = MakeGlBuffer(std::size_t{capacity} * static_cast<std::size_t>(lane.format.stride), nullptr, GL_DYNAMIC_STORAGE_BIT);
    if (pool.capacity > 0) {
      glCopyNamedBufferSubData(lane.buffer.get(), grown.get(), 0, 0,
                               static_cast<GLsizeiptr>(std::size_t{pool.capacity} * static_cast<std::size_t>(lane.format.stride)));
    }
    lane.buffer = std::move(grown);
  }
  // The new room, joined to a free range that ends where the old room did.
  std::uint32_t first = pool.capacity, count = capacity - pool.capacity;
  if (!pool.free.empty()) {
    auto last = std::prev(pool.free.end());
    if (last->first + last->second == first) {
      first = last->first;
      count += last->second;
      pool.free.erase(last);
    }
  }
  pool.free[first] = count;
  pool.capacity = capacity;
  BuildVertexArray(pool);
  CheckGlError("growing the GPU's block buffers");
}

std::uint32_t GpuBlockArena::Allocate(Pool& pool, std::uint32_t count) {
  for (;;) {
    for (auto it = pool.free.begin(); it != pool.free.end(); ++it) {
      if (it->second < count) continue;
      const std::uint32_t first = it->first, left = it->second - count;
      pool.free.erase(it);
      if (left > 0) pool.free[first + count] = left;
      return first;
    }
    Grow(pool, count);
  }
}

std::uint32_t GpuBlockArena::AllocateSlot() {
  if (!free_slots_.empty()) {
    const std::uint32_t slot = free_slots_.back();
    free_slots_.pop_back();
    return slot;
  }
  if (slots_used_ == slot_capacity_) {
    const std::uint32_t capacity = std::max(kFirstSlots, 2 * slot_capacity_);
    GlBuffer grown = MakeGlBuffer(std::size_t{capacity} * sizeof(GpuBlockParameters), nullptr, GL_DYNAMIC_STORAGE_BIT);
    if (slot_capacity_ > 0) {
      glCopyNamedBufferSubData(parameters_.get(), grown.get(), 0, 0,
                               static_cast<GLsizeiptr>(std::size_t{slot_capacity_} * sizeof(GpuBlockParameters)));
    }
    parameters_ = std::move(grown);
    slot_capacity_ = capacity;
  }
  return slots_used_++;
}

GpuBlockArena::Placement GpuBlockArena::Place(std::span<const GpuColumnBytes> columns, std::uint32_t count,
                                              const GpuBlockParameters& parameters) {
  Placement placement;
  placement.pool = PoolFor(columns);
  Pool& pool = *pools_[placement.pool];
  placement.count = count;
  placement.first = count > 0 ? Allocate(pool, count) : 0;
  placement.slot = AllocateSlot();
  for (const Pool::Lane& lane : pool.lanes) {
    if (count == 0) break;
    const auto column = std::find_if(columns.begin(), columns.end(), [&](const GpuColumnBytes& c) { return c.id == lane.id; });
    const std::size_t stride = static_cast<std::size_t>(lane.format.stride), bytes = std::size_t{count} * stride;
    if (column->bytes.size() < bytes) {
      throw Error::InvalidArgument(std::string("column '") + ColumnName(lane.id) + "' holds " +
                                   std::to_string(column->bytes.size()) + " bytes, fewer than " + std::to_string(count) +
                                   " points take");
    }
    uploads_.Upload(column->bytes.first(bytes), lane.buffer.get(), std::size_t{placement.first} * stride);
  }
  uploads_.Upload({reinterpret_cast<const std::uint8_t*>(&parameters), sizeof parameters}, parameters_.get(),
                  std::size_t{placement.slot} * sizeof(GpuBlockParameters));
  CheckGlError("uploading a block");
  return placement;
}

void GpuBlockArena::Release(const Placement& placement) {
  free_slots_.push_back(placement.slot);
  if (placement.count == 0) return;
  Pool& pool = *pools_.at(placement.pool);
  std::uint32_t first = placement.first, count = placement.count;
  auto next = pool.free.lower_bound(first);
  if (next != pool.free.end() && first + count == next->first) {
    count += next->second;
    next = pool.free.erase(next);
  }
  if (next != pool.free.begin()) {
    auto previous = std::prev(next);
    if (previous->first + previous->second == first) {
      previous->second += count;
      return;
    }
  }
  pool.free[first] = count;
}

}  // namespace octocosm
