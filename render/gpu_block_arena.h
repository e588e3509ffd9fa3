// Where resident blocks live on the GPU: a few large buffers instead of a
// buffer and a vertex array per block, so that a frame draws every block of
// an epoch with one multi-draw-indirect call per column layout rather than a
// draw call, a vertex-array switch and a uniform-block switch per block.
//
// Blocks with the same columns (and ID encoding) share a pool: one buffer
// per column, fetched as vertex attributes at a fixed stride, and one vertex
// array object. A block occupies a contiguous range of point indices in its
// pool (first-fit, freed ranges coalesce; a full pool doubles, copying on the
// GPU). Its decode parameters take a slot in one storage buffer
// ("Blocks" in shaders/splat_vert.glsl). Leaves and clusters differ in
// columns (clusters carry shapes and dispersions), so a frame uses two or
// three pools.
//
// Blocks are uploaded through a persistently mapped staging ring
// (render/upload_ring.h). Every vertex array also reads a per-instance draw
// index (0, 1, 2, ...):
// a draw's base instance picks its record in the "Draws" storage buffer
// (render/splat_renderer.h), which core OpenGL 4.5 allows without
// gl_DrawID.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <vector>

#include "index/block_codec.h"
#include "render/gl_objects.h"
#include "render/upload_ring.h"

namespace octocosm {

// The uniform data of one block as the shader reads it (std430 layout of
// "BlockParams" in shaders/splat_vert.glsl).
struct GpuBlockParameters {
  float node[4];
  std::int32_t columns[3][4];
  float ranges[5][2][4];  // velocity, displacement, next_velocity, prev_displacement, prev_velocity: min, step
  std::uint32_t id_base[4];  // the id column's base (encoding 2), low word first; 0 for u64 IDs
  float dispersion[4];       // the velocity dispersion column's minimum and step
  // The cluster cut (render/cluster_links.h): the bases of the block's own
  // refine_bound codes and its node's quantum; its parent's bases and quantum.
  float refine[2][4];
};
static_assert(sizeof(GpuBlockParameters) == 288);

// One column's bytes of a block, as stored.
struct GpuColumnBytes {
  ColumnId id;
  std::uint8_t encoding;
  std::span<const std::uint8_t> bytes;
};

class GpuBlockArena {
 public:
  struct Placement {
    std::uint32_t pool = 0;
    std::uint32_t first = 0;  // point index in the pool
    std::uint32_t count = 0;
    std::uint32_t slot = 0;   // in the parameters buffer
  };

  GpuBlockArena();
  GpuBlockArena(const GpuBlockArena&) = delete;
  GpuBlockArena& operator=(const GpuBlockArena&) = delete;
  ~GpuBlockArena();

  // Copies `count` points' columns into the pool of their layout and the
  // parameters into a slot. Throws Error::InvalidArgument when a column holds
  // fewer bytes than `count` points take, Error::NotSupported when the GPU
  // is out of memory.
  Placement Place(std::span<const GpuColumnBytes> columns, std::uint32_t count, const GpuBlockParameters& parameters);
  void Release(const Placement& placement);

  std::size_t pool_count() const { return pools_.size(); }
  GLuint vertex_array(std::uint32_t pool) const;
  // A pool's column buffers, for reading them as storage buffers (the
  // compute path, render/compute_splatter.h): point i of a column starts at
  // byte stride * i of its buffer, which holds capacity points.
  struct ColumnBuffer {
    ColumnId id;
    GLuint buffer;
    std::uint32_t stride;
  };
  std::vector<ColumnBuffer> column_buffers(std::uint32_t pool) const;
  std::uint32_t capacity(std::uint32_t pool) const;
  // Whether the pool's IDs are u32 offsets from each block's base (one word
  // a point) rather than whole u64 IDs (two).
  bool id_offsets(std::uint32_t pool) const;
  GLuint parameters() const { return parameters_.get(); }
  // Makes the per-instance draw index count at least `draws`.
  void ReserveDrawIndices(std::size_t draws);
  // Bytes the buffers take on the GPU.
  std::size_t gpu_bytes() const;

 private:
  struct Pool;
  std::uint32_t PoolFor(std::span<const GpuColumnBytes> columns);
  std::uint32_t Allocate(Pool& pool, std::uint32_t count);
  void Grow(Pool& pool, std::uint32_t at_least);
  void BuildVertexArray(Pool& pool);
  std::uint32_t AllocateSlot();

  std::vector<std::unique_ptr<Pool>> pools_;
  GlBuffer parameters_;
  std::uint32_t slot_capacity_ = 0;
  std::vector<std::uint32_t> free_slots_;
  std::uint32_t slots_used_ = 0;
  GlBuffer draw_indices_;
  std::size_t draw_index_capacity_ = 0;
  UploadRing uploads_;  // every block's bytes and parameters reach the GPU through it
};

}  // namespace octocosm
