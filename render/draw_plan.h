// What to draw of a level-of-detail frontier while its blocks are still
// arriving: never a hole where an ancestor is loaded, never a region drawn
// twice.
//
// A selected node that is loaded is drawn in its octants in view, which its
// block tells once it is loaded (how far its blobs reach beyond each octant):
// whole where the view holds it. A refined node (one the
// frontier replaced by its children) is "covered" when it is loaded or when
// every one of its children in view is covered; an unloaded selected node is
// not covered. Drawing a covered refined node means, octant by octant: the
// child's drawing when the child is covered, otherwise the node's own points
// of that octant (its blocks keep each child octant's points contiguous,
// index/node_points.h), which stand for the child's subtree at a coarser
// level with the same mass. Octants whose child is out of view or absent are
// skipped. Nodes that are not covered draw what they can of their children,
// leaving holes only where no ancestor is loaded (at start-up).
//
// When every selected node is loaded the plan is exactly the selected nodes'
// octants in view.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "index/node_hierarchy.h"
#include "query/lod_frontier.h"
#include "render/cluster_links.h"

namespace octocosm {

struct DrawRange {
  std::int32_t node = -1;   // hierarchy index
  std::uint32_t first = 0;  // first point of the node's block
  std::uint32_t count = 0;  // points to draw
  CutRole cut = CutRole::kNone;
};

struct DrawPlan {
  std::vector<DrawRange> ranges;
  std::uint64_t points = 0;
  std::uint64_t stand_ins = 0;  // octant ranges of parents drawn for children not loaded yet
};

// `loaded(node)` says whether a node's block is ready to draw;
// `octant_offsets(node)` gives the 9 octant offsets of a loaded node's block;
// `octants_in_view(node)`, a bit per octant of a loaded selected node that
// may be seen (bit o: octant o; empty function: all of them).
DrawPlan PlanDraws(const NodeHierarchy& hierarchy, const LodFrontier& frontier,
                   const std::function<bool(std::int32_t)>& loaded,
                   const std::function<std::array<std::uint32_t, 9>(std::int32_t)>& octant_offsets,
                   const std::function<std::uint8_t(std::int32_t)>& octants_in_view = {});

// The draws of a cluster frontier (query/cluster_frontier.h), whose nodes
// are all drawn, each taking its part in the cut: every loaded node
// reached, in the octants in view, its points drawn with CutRole::kCut
// where the child of the octant is drawn too and kCutFinal where it is not
// (not reached, not loaded, or absent). A node reached whose parent is not
// drawn is not drawn either (the frontier reaches none such: a child is
// reached through its loaded parent).
DrawPlan PlanClusterDraws(const NodeHierarchy& hierarchy, const LodFrontier& frontier,
                          const std::function<bool(std::int32_t)>& loaded,
                          const std::function<std::array<std::uint32_t, 9>(std::int32_t)>& octant_offsets,
                          const std::function<std::uint8_t(std::int32_t)>& octants_in_view = {});

}  // namespace octocosm
