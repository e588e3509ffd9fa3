// Node selection: which octree nodes of one epoch a query reads, found by
// walking the block index from the root and culling node cubes against the
// query region. Only index entries are touched here, never a block.
//
// Two levels of detail:
//
//  - a level L: the nodes at level L plus the leaves shallower than L, which
//    together cover the data exactly once at that resolution;
//
//  - a screen-space error for a camera: a node is refined (replaced by its
//    children) while its projected point spacing exceeds the threshold,
//
//        spacing_px = size / cbrt(points) / distance * height / (2 tan(fov_y / 2))
//
//    where size is the node edge, points its point count, distance the
//    distance from the camera position to the nearest point of the node cube
//    (at least the camera's near distance) and height the viewport height in
//    pixels. The selection is the refinement frontier: no selected node is an
//    ancestor of another, and every leaf that meets the region has exactly one
//    selected ancestor-or-self. A smaller threshold refines a superset of
//    nodes.
//
// A node's children are found with one index scan of its eight child keys
// (contiguous in key order); a node without children is a leaf.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "index/dataset.h"
#include "query/frustum.h"
#include "query/region.h"

namespace octocosm {

struct SelectionStats {
  std::uint64_t nodes_visited = 0;     // index entries examined
  std::uint64_t index_scans = 0;       // child look-ups (one per refined node)
  // Index pages the epoch's page file read from disk (and bytes) during the
  // walk; pages found decoded in its cache cost nothing. Taken from the page
  // file's counters, so they include the reads of any query running on the
  // same store at the same time.
  std::uint64_t index_pages_read = 0;
  std::uint64_t index_bytes_read = 0;
};

struct ScreenErrorView {
  Camera camera;
  double viewport_height = 1080;  // pixels, > 0
  double threshold_pixels = 1;    // > 0
};

// The index entries of the selected nodes, in the order of their blocks in the
// page file (ascending first page), for sequential reads. Throws
// Error::InvalidArgument for an epoch or level out of range; Error from the
// store when the index cannot be read.
std::vector<IndexEntry> SelectLevel(const Dataset& dataset, std::uint32_t epoch, const Region& region, int level,
                                    SelectionStats& stats);
std::vector<IndexEntry> SelectByScreenError(const Dataset& dataset, std::uint32_t epoch, const Region& region,
                                            const ScreenErrorView& view, SelectionStats& stats);

// The projected point spacing of a node in pixels (the formula above).
double ScreenSpaceError(const NodeCube& node, std::uint64_t points, const ScreenErrorView& view);

// ScreenSpaceError for many nodes seen from one view, the view's part of the
// formula computed once; the same numbers.
class ScreenErrorMeter {
 public:
  explicit ScreenErrorMeter(const ScreenErrorView& view);
  double operator()(const NodeCube& node, std::uint64_t points) const;

 private:
  std::array<double, 3> position_;
  double near_;
  double pixels_per_unit_at_unit_distance_;
};

}  // namespace octocosm
