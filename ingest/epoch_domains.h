// How one epoch is cut among the ranks that ingest it together
// (ingest/ingest.h, IngestSpreadInto): each rank builds the subtrees of some
// nodes, its domains, and the levels above every rank's domains are merged
// from their roots.
//
// The cut is made on a grid of cells `level` levels below the root, from
// the number of points in each (summed over the ranks). A node holding at
// most the tree's leaf capacity is a leaf however its points are spread, so
// it is never cut: such a node, or a cell of the grid, is a unit. Units in
// depth-first order are shared out in consecutive runs of about equal
// points; each rank's domains are then the highest nodes all of whose units
// are that rank's. So every domain's subtree is one rank's whole, and the
// tree the ranks build together is the one a single process builds.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "index/cube.h"
#include "index/morton.h"

namespace octocosm {

struct EpochDomains {
  int level = 0;                     // of the grid's cells
  std::vector<NodeKey> keys;         // every rank's domains, in depth-first order
  std::vector<int> owner;            // keys[i]'s rank; nondecreasing
  std::vector<std::uint32_t> cell_domain;  // index into keys of each cell's domain (cells without points: any)

  // The grid's cell that `point` falls in, as an index into cell counts.
  static std::uint64_t CellIndex(const Cube& cube, const double* point, int level);
  // The domains of `rank`, in depth-first order.
  std::vector<NodeKey> DomainsOf(int rank) const;
};

// The grid level for an epoch of a tree of depth limit `max_level`: 8^level
// cells balance the ranks' shares finely and cost 8 bytes each to sum.
int DomainGridLevel(int max_level);

// Shares the cells' points (`cell_counts`, 8^level of them, in Morton
// order) among `ranks`. Throws InvalidArgument for a count array of the
// wrong size or no ranks.
EpochDomains ShareDomains(std::span<const std::uint64_t> cell_counts, int level, std::uint64_t leaf_capacity,
                          int ranks);

}  // namespace octocosm
