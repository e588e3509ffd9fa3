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
#include <memory>
#include <span>
#include <string>

#include "index/block_codec.h"
#include "index/cube.h"
#include "render/cluster_links.h"
#include "render/gpu_block_arena.h"

namespace octocosm {

// A block drawn by the cluster-by-cluster level of detail takes, besides its
// columns, the cut's entries (render/cluster_links.h): its own bound codes
// and those of each point's parent cluster, gathered from the parent's links.
struct ClusterCutUpload {
  const ClusterLinks* parent = nullptr;  // the parent's links; null for the root
  NodeCube parent_node;
  std::uint64_t first_entry = 0;  // the block's first point among the parent's child_cluster entries
};

class GpuBlock {
 public:
  // Uploads the block `bytes` (a whole block or a column subset of one,
  // query/column_reader.h) whose verified header is `header`, of node cube
  // `node`, into `arena`, which must outlive it; with `cut`, the cut's
  // entries too. Needs a current GL context. Throws Error::NotSupported when
  // the GPU is out of memory, Error::Corruption (naming `where`) when a
  // column's bytes lie outside `bytes` or are too few for the block's points,
  // or its links do not fit its parent's.
  static GpuBlock Upload(GpuBlockArena& arena, std::span<const std::uint8_t> bytes, const BlockHeader& header,
                         const NodeCube& node, const std::string& where, const ClusterCutUpload* cut = nullptr);

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
  // Its links to its children's points, when its block has them.
  const ClusterLinks* links() const { return links_.get(); }
  // Whether it was uploaded with the cut's entries, and its parent's cube
  // (its root's own when it has none).
  bool has_cut() const { return has_cut_; }
  bool has_parent() const { return has_parent_; }
  const NodeCube& parent_node() const { return parent_node_; }
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
  std::unique_ptr<const ClusterLinks> links_;
  bool has_cut_ = false;
  bool has_parent_ = false;
  NodeCube parent_node_;
};

}  // namespace octocosm
