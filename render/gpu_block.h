// One block's columns on the GPU, as they are stored (index/block_codec.h):
// the CPU verifies checksums and copies bytes into the block arena's shared
// buffers (render/gpu_block_arena.h), the vertex shader decodes. Columns are
// fetched as vertex attributes (their encodings are attribute formats: u16 x
// 3, u32, u16, u8, u32 x 2), which GL drivers fetch far faster than shader
// loads from a storage buffer; the block's decode parameters take a slot of
// the arena's parameters buffer. Columns are little endian, as GL reads them
// on little-endian hosts. A GpuBlock gives its room back when destroyed.
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "index/block_codec.h"
#include "index/cube.h"
#include "render/gpu_block_arena.h"

namespace octocosm {

class GpuBlock {
 public:
  // Uploads the block `bytes` (a whole block or a column subset of one,
  // query/column_reader.h) whose verified header is `header`, of node cube
  // `node`, into `arena`, which must outlive it. Needs a current GL context.
  // Throws Error::NotSupported when the GPU is out of memory,
  // Error::Corruption (naming `where`) when a column's bytes lie outside
  // `bytes` or are too few for the block's points.
  static GpuBlock Upload(GpuBlockArena& arena, std::span<const std::uint8_t> bytes, const BlockHeader& header,
                         const NodeCube& node, const std::string& where);

  GpuBlock(GpuBlock&& other) noexcept;
  GpuBlock& operator=(GpuBlock&& other) noexcept;
  GpuBlock(const GpuBlock&) = delete;
  GpuBlock& operator=(const GpuBlock&) = delete;
  ~GpuBlock();

  // Where it lies: the pool, its first point there, its parameters' slot.
  const GpuBlockArena::Placement& placement() const { return placement_; }
  std::uint32_t point_count() const { return point_count_; }
  const std::array<std::uint32_t, 9>& octant_offsets() const { return octant_offsets_; }
  // How far the blobs of each octant's points reach from their centres at
  // most (world units): how much the octant's cube grows before it is culled.
  const std::array<double, 8>& octant_reach() const { return octant_reach_; }
  const NodeCube& node() const { return node_; }
  // The columns it holds.
  ColumnSet columns() const { return columns_; }
  std::size_t gpu_bytes() const { return gpu_bytes_; }

 private:
  GpuBlock() = default;

  GpuBlockArena* arena_ = nullptr;
  GpuBlockArena::Placement placement_;
  std::uint32_t point_count_ = 0;
  std::array<std::uint32_t, 9> octant_offsets_{};
  std::array<double, 8> octant_reach_{};
  NodeCube node_;
  ColumnSet columns_ = 0;
  std::size_t gpu_bytes_ = 0;
};

}  // namespace octocosm
