// Coarse points that stand for clusters: how an inner node summarises the
// points below it so that its picture approaches the full one with few
// points (the other way is index/sampler.h's random subselection).
//
// The node's population (its children's points, each with a weight and a
// blob of its own) is first cut by the node's octants and, inside each, by
// particle type, so every cluster lies inside one child (a child's clusters
// carry its subtree's mass exactly) and is of one type. Then, again and
// again, the cell whose error would show most is cut in two, until one
// more cut would make more than `capacity` cells (or no cell can be cut:
// each holds one point, or points that coincide):
//
//  - The error of a cell drawn as one blob: its mass M times how much of
//    its blob's width is the members' spread rather than their own blobs,
//        E = M s^2 / (s^2 + v + p^2),
//    s^2 the members' spread (mass-weighted, per axis), v their own blobs'
//    mean variance, p the size of a pixel where a frontier draws the node,
//    taken as an eighth of the node's mean point spacing (edge /
//    cbrt(capacity) / 8: a node is drawn when its spacing projects to a few
//    pixels). A heavy but compact cell (a halo's core seen from afar, or
//    members whose blobs already overlap) costs little; a spread-out one
//    costs its mass. Cutting by mass alone spent clusters on cores no
//    pixel resolves.
//  - The cut: across the cell's principal axis (the direction of its
//    largest spread), at the place that leaves the least summed squared
//    distance of the members from the two halves' centres, found over
//    kCutBins bins of the members' projections. Cells follow the
//    structure: a filament is cut into pieces along it, not into cubes
//    that straddle it, and a piece's blob (index/cluster_shape.h) has its
//    members' moments.
// Measured against the reference pictures, this is 1.6-4.2 dB closer than
// octree cells cut heaviest first, at the same number of points
// (docs/ACCURACY.md section 6).
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
// (NodePoints::velocity_dispersion).
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

// Bins over a cell's extent along its principal axis in which the best cut
// is sought.
inline constexpr int kCutBins = 1024;

struct Clusters {
  // Population indices, cluster by cluster; cluster c's members are
  // member[begin[c]] .. member[begin[c + 1] - 1]. Clusters are ordered by
  // the child octant of the node that holds them.
  std::vector<std::uint32_t> member;
  std::vector<std::uint32_t> begin;  // size() + 1 entries

  std::size_t size() const { return begin.empty() ? 0 : begin.size() - 1; }
};

// Cuts the population of node `key` into at most `capacity` clusters, each
// of one type (capacity >= 8 x the number of types present). The
// population: its points' finest grid coordinates (all inside the node),
// weights > 0, each point's own blob variance per axis in units of the
// node's edge squared (>= 0; empty: points without blobs), and particle
// types (or none). Deterministic: the same population in the same order
// gives the same clusters (each cluster's members in ascending index
// order). Throws Error::InvalidArgument on mismatched lengths or too small a
// capacity.
Clusters ClusterPopulation(std::span<const GridPoint> grid, std::span<const double> weight,
                           std::span<const double> own_variance, std::span<const std::uint8_t> type, NodeKey key,
                           std::size_t capacity);

}  // namespace octocosm
