// What the renderer keeps on the CPU of a block whose points are clusters
// linked to its children's points (index/block_codec.h, columns 13 and 14),
// for the level of detail that refines cluster by cluster
// (query/cluster_frontier.h, docs/RENDERING.md):
// - the bounds of each child octant's clusters, and each cluster's, from
//   which the frontier tells whether the child is needed;
// - each cluster's position and bound codes as stored, and the link from
//   each child point to its cluster, from which a child's upload gathers,
//   for each of its points, its parent cluster's position and bounds. With
//   them the GPU evaluates the parent's error in the child's draw exactly as
//   the parent's own draw evaluates it (the same codes, the same float
//   arithmetic), so that each particle is drawn once.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "index/block_codec.h"
#include "index/cube.h"
#include "query/cluster_frontier.h"

namespace octocosm {

// A draw's part in the cluster cut (docs/FORMAT.md section 4), for a block
// uploaded with the cut's entries (GpuBlock::has_cut): none (every point
// drawn); its points drawn where their own error is at most tau and their
// parent's above it; or where their parent's is above tau whatever their
// own, for points below which nothing is drawn (a child not loaded, out of
// view, or not needed). The root's points have no parent to ask.
enum class CutRole : std::uint8_t { kNone, kCut, kCutFinal };

// A point's entry of the GPU's cut column (render/gpu_block_arena.h): its
// own bound codes (R, a, r; 0 for a leaf's particles) and its parent
// cluster's, each of the parent's three words its position code k in the
// low half and its bound code k in the high half (0 for the root).
struct ClusterCutEntry {
  std::uint16_t own[3];
  std::uint16_t unused;
  std::uint32_t parent[3];
};
static_assert(sizeof(ClusterCutEntry) == 20);

class ClusterLinks {
 public:
  // The links of the block `bytes` (`header`, of node cube `node`), or null
  // when it has neither column. Throws Error::Corruption naming `where` when
  // a column is damaged, or one is there without the other or the positions.
  static std::unique_ptr<const ClusterLinks> FromBlock(std::span<const std::uint8_t> bytes, const BlockHeader& header,
                                                       const NodeCube& node, const std::string& where);

  const NodeRefineBounds& refine_bounds() const { return bounds_; }
  const std::array<std::int32_t, 3>& bases() const { return bases_; }
  std::uint32_t cluster_count() const { return static_cast<std::uint32_t>(codes_.size() / 3); }
  // Entries of the child_cluster column: the children's points.
  std::uint64_t entry_count() const { return child_cluster_.size(); }
  // Sets the own words of out[i] from cluster i, for i < out.size() (at most
  // cluster_count()).
  void SetOwnBounds(std::span<ClusterCutEntry> out) const;
  // Sets the parent words of out[i] from entry first + i, for i < out.size().
  // Throws Error::Corruption naming `where` (the child) when the entries run
  // past the column: the child holds points its parent does not link.
  void GatherParents(std::uint64_t first, std::span<ClusterCutEntry> out, const std::string& where) const;

 private:
  ClusterLinks() = default;

  std::vector<std::uint16_t> position_;  // 3 codes per cluster, as stored
  std::vector<std::uint16_t> codes_;     // 3 bound codes per cluster, as stored
  std::vector<std::uint32_t> child_cluster_;
  std::array<std::int32_t, 3> bases_{};
  NodeRefineBounds bounds_;
};

}  // namespace octocosm
