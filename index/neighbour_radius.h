// The smoothing length astrophysicists give a particle that has none of its
// own: the radius of the smallest sphere around it that holds its k nearest
// neighbours, the particle itself counted (GADGET's and SPLASH's convention
// for the support radius of an SPH kernel; k = 32 by default). The kernel
// then reaches exactly as far as the k-th neighbour.
//
// NeighbourRadii answers that radius for query points against a fixed set of
// points, with a k-d tree (nanoflann, Debian's libnanoflann-dev) in double
// precision: exact, no approximation. It knows nothing of periodic boxes or of
// points not in its set; ingest/smoothing_pass.h loads the right neighbours
// (halos across region borders, periodic images) and checks that a sphere lay
// inside what was loaded.
#pragma once

#include <cstddef>
#include <limits>
#include <memory>
#include <span>
#include <vector>

namespace octocosm {

inline constexpr int kDefaultNeighbours = 32;

class NeighbourRadii {
 public:
  // `positions` holds 3 * n coordinates, x,y,z interleaved; it must outlive
  // this object and stay unchanged. Builds a tree (about n log n) for each
  // block of consecutive points, blocks side by side on up to `threads`
  // threads (0: all cores); block b starts at point block_begins[b] (the
  // first at 0, ascending; empty: one block of all points). A query
  // searches one block, then the others only where their boxes come nearer
  // than the k-th neighbour found so far, so the answer does not depend on
  // the cut; the search is fastest when the blocks are compact and apart
  // (ingest/smoothing_pass.h cuts them as octree cells).
  explicit NeighbourRadii(std::span<const double> positions, std::span<const std::size_t> block_begins = {},
                          int threads = 1);
  ~NeighbourRadii();
  NeighbourRadii(const NeighbourRadii&) = delete;
  NeighbourRadii& operator=(const NeighbourRadii&) = delete;

  std::size_t size() const { return count_; }
  std::size_t blocks() const { return blocks_.size(); }

  // The distance from `query` (3 coordinates) to its k-th nearest point of
  // the set, counting a point at the query itself; infinity when the set has
  // fewer than k points. k >= 1. `first_block` (< blocks()) is searched
  // first: the answer is the same whichever it is, but it comes fastest from
  // the block that holds the query's neighbours. Thread-safe (the trees are
  // read only).
  //
  // `bound`, when finite, is an upper bound of the answer that the caller
  // knows: a query's radius is at most a nearby query's radius plus the
  // distance between the two, so callers that search in spatial order pass
  // that. The search then skips everything farther from the start instead of
  // narrowing down from infinity. A bound below the answer costs a second
  // search, never a wrong answer.
  double Radius(const double* query, int k, std::size_t first_block = 0,
                double bound = std::numeric_limits<double>::infinity()) const;

 private:
  struct Block;
  std::size_t count_;
  std::vector<std::unique_ptr<Block>> blocks_;
};

}  // namespace octocosm
