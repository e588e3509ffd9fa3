// One block's columns on the GPU, as they are stored (index/block_codec.h):
// the CPU verifies checksums and copies bytes, the vertex shader decodes.
// Each column starts on a 16-byte boundary of one buffer and is fetched as a
// vertex attribute (a vertex array object per block; the columns' encodings
// are attribute formats: u16 x 3, u32, u16, u8, u32 x 2), which GL drivers
// fetch far faster than shader loads from a storage buffer. A small uniform
// buffer holds the block's decode parameters (shaders/splat_vert.glsl,
// uniform block "Block"). Columns are little endian, as GL reads them on
// little-endian hosts.
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "index/block_codec.h"
#include "index/cube.h"
#include "render/gl_objects.h"

namespace octocosm {

class GpuBlock {
 public:
  // Uploads the block `bytes` (a whole block or a column subset of one,
  // index/column_reader.h) whose verified header is `header`, of node cube
  // `node`. Needs a current GL context. Throws Error::NotSupported when the
  // GPU is out of memory, Error::Corruption (naming `where`) when a column's
  // bytes lie outside `bytes`.
  static GpuBlock Upload(std::span<const std::uint8_t> bytes, const BlockHeader& header, const NodeCube& node,
                         const std::string& where);

  GLuint vertex_array() const { return vertex_array_.get(); }
  GLuint parameters() const { return parameters_.get(); }
  std::uint32_t point_count() const { return point_count_; }
  const std::array<std::uint32_t, 9>& octant_offsets() const { return octant_offsets_; }
  const NodeCube& node() const { return node_; }
  // The columns it holds.
  ColumnSet columns() const { return columns_; }
  std::size_t gpu_bytes() const { return gpu_bytes_; }

 private:
  GlBuffer buffer_;
  GlVertexArray vertex_array_;
  GlBuffer parameters_;
  std::uint32_t point_count_ = 0;
  std::array<std::uint32_t, 9> octant_offsets_{};
  NodeCube node_;
  ColumnSet columns_ = 0;
  std::size_t gpu_bytes_ = 0;
};

}  // namespace octocosm
