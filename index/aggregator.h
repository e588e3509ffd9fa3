// Coarse points that stand for clusters: how an inner node summarises the
// points below it so that its picture approaches the full one with few
// points (the other way is index/sampler.h's random subselection).
//
// The node's population (its children's points, each with a weight) is cut
// by particle type and by an adaptive octree inside the node's cube: the
// heaviest cell is split
// into its octants first, again and again, until one more split would make
// more than `capacity` cells (or no cell can be split: each holds one point,
// or lies at the finest grid). The first split is the node's own octants,
// so every cluster lies inside one child and a child's clusters carry its
// subtree's mass exactly. Splitting by mass puts the clusters where the mass
// is: a halo's core keeps its points one by one while a void becomes a few
// broad blobs.
//
// Each cluster becomes one point (subtree_builder.h, AggregateParent):
// weight the members' sum, position their centre of mass, and a smoothing
// length whose blob has the members' spread: the mass-weighted mean of each
// member's squared distance from the centre (per axis, a third of it) plus
// its own blob's variance, turned back into a kernel radius
// (KernelRadiusForVariance). With velocities, the point has their
// mass-weighted mean velocity and their one-dimensional rms velocity
// dispersion about it, sigma^2 = sum w (|v - vbar|^2 + 3 sigma_member^2) /
// (3 W): a member that is itself a cluster brings its own, so a cluster of
// clusters has the dispersion of all the particles below it
// (NodePoints::velocity_dispersion). A measured 2-D experiment beside this
// project found such clusters 5-20 dB closer to the full picture than a
// random subsample of as many points, and the members' own blob width
// essential.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "index/cube.h"
#include "index/morton.h"

namespace octocosm {

// Per-axis variance of a blob of smoothing length h drawn with the
// renderer's 2-D cubic spline of support radius h (render/splat_kernel.h):
// 31/392 h^2.
inline constexpr double kKernelVariancePerH2 = 31.0 / 392.0;

inline double KernelVariance(double h) { return kKernelVariancePerH2 * h * h; }
double KernelRadiusForVariance(double variance);

struct Clusters {
  // Population indices, cluster by cluster; cluster c's members are
  // member[begin[c]] .. member[begin[c + 1] - 1]. Clusters are ordered by
  // the child octant of the node that holds them.
  std::vector<std::uint32_t> member;
  std::vector<std::uint32_t> begin;  // size() + 1 entries

  std::size_t size() const { return begin.empty() ? 0 : begin.size() - 1; }
};

// Cuts the population of node `key` (its points' finest grid coordinates,
// all inside the node, weights > 0, and particle types, or none) into at
// most `capacity` clusters, each of one type (capacity >= 8 x the number of
// types present). Deterministic: the same population in the same order
// gives the same clusters (each cluster's members in ascending index
// order). Throws Error::InvalidArgument on mismatched lengths or too small a
// capacity.
Clusters ClusterPopulation(std::span<const GridPoint> grid, std::span<const double> weight,
                           std::span<const std::uint8_t> type, NodeKey key, std::size_t capacity);

}  // namespace octocosm
