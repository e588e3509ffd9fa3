// The level of detail of one frame: which nodes of an epoch a renderer draws
// for a camera, within a pixel threshold and a point budget, most important
// first. Works on a NodeHierarchy in memory: no I/O.
//
// Starting from the root, nodes are taken in order of their screen-space
// error (query/node_selection.h: projected point spacing in pixels, largest
// first). A node whose error exceeds the threshold and that has children is
// refined: replaced by its children whose cubes meet the view frustum (the
// others are culled). Refining adds the children's points and removes the
// node's; a node whose refinement would exceed the point budget is drawn as
// it is, and the nodes after it are still refined where their children fit
// in what is left. So the budget is spent where the picture needs it most,
// then filled, and the selection never exceeds the budget unless the root
// alone does.
//
// The selection is a frontier: no selected node is an ancestor of another,
// and (for nodes in view) every leaf below a refined node has exactly one
// selected ancestor-or-self. `load_order` lists refined and selected nodes in
// the order they were taken: coarse before fine, the order in which a
// streaming renderer should fetch blocks so that a parent can stand in for
// children that have not arrived.
#pragma once

#include <cstdint>
#include <vector>

#include "index/cube.h"
#include "index/node_hierarchy.h"
#include "query/frustum.h"
#include "query/node_selection.h"
#include "query/view_culler.h"

namespace octocosm {

struct LodOptions {
  double pixel_threshold = 1;    // refine while the projected point spacing exceeds this (pixels, > 0)
  std::uint64_t point_budget = 0;  // most points to select; 0: no limit
  // World units by which node cubes grow before the frustum test: points
  // moved by time interpolation may leave their node's cube
  // (query/view_culler.h).
  double cull_margin = 0;
};

struct LodFrontier {
  std::vector<std::int32_t> selected;    // nodes to draw
  std::vector<std::int32_t> refined;     // nodes replaced by their children
  std::vector<std::int32_t> load_order;  // refined and selected nodes, most important first
  std::uint64_t points = 0;              // points in the selected nodes
  std::uint64_t nodes_visited = 0;
  std::uint64_t nodes_culled = 0;
  bool budget_reached = false;           // some node was left unrefined for the budget
  // The test nodes were culled by: a renderer culls the octants of selected
  // nodes with it, once their blocks tell how far their blobs reach.
  ViewCuller culler;
};

// Throws Error::InvalidArgument for a threshold that is not > 0 or a negative
// margin; the camera is validated.
LodFrontier SelectLodFrontier(const NodeHierarchy& hierarchy, const Cube& cube, const ScreenErrorView& view,
                              const LodOptions& options);

}  // namespace octocosm
