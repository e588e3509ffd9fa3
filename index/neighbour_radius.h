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
#include <memory>
#include <span>

namespace octocosm {

inline constexpr int kDefaultNeighbours = 32;

class NeighbourRadii {
 public:
  // `positions` holds 3 * n coordinates, x,y,z interleaved; it must outlive
  // this object and stay unchanged. Builds the tree (about n log n).
  explicit NeighbourRadii(std::span<const double> positions);
  ~NeighbourRadii();
  NeighbourRadii(const NeighbourRadii&) = delete;
  NeighbourRadii& operator=(const NeighbourRadii&) = delete;

  std::size_t size() const { return count_; }

  // The distance from `query` (3 coordinates) to its k-th nearest point of
  // the set, counting a point at the query itself; infinity when the set has
  // fewer than k points. k >= 1. Thread-safe (the tree is read only).
  double Radius(const double* query, int k) const;

 private:
  struct Tree;
  std::size_t count_;
  std::unique_ptr<Tree> tree_;
};

}  // namespace octocosm
