// Density-weighted priority sampling: which points of a node's population an
// inner node keeps, and what weight and smoothing length each kept point gets.
//
// The population of an inner node is the union of its children's points,
// each with a weight w_i > 0 (the mass it stands for). The node keeps n of
// them:
//
// 1. Local density. The node's cube is divided into a fine grid of 2^b cells
//    per axis (b = density_grid_bits, default 5); rho_i is the population's
//    weight in point i's fine cell divided by the cell volume.
//
// 2. Importance. s_i = w_i * rho_i^(-alpha). alpha = 0 samples in proportion
//    to mass, so dense regions dominate; alpha = 1 gives every occupied fine
//    cell the same total importance; the default 0.5 sits between, thinning
//    sparse regions less so that voids and faint filaments keep their shape.
//    (Scaling all rho by a constant changes nothing below, so the cell
//    volume is never formed.)
//
// 3. Priority sampling (N. Duffield, C. Lund, M. Thorup, "Priority sampling
//    for estimation of arbitrary subset sums", J. ACM 54(6), 2007). Each
//    point draws u_i in (0, 1] from a hash of its sampling ID, the seed and
//    the node's level, so the draw is deterministic: the same particle gets
//    the same u at a given level in every epoch (no flicker when playing a
//    time series), and the selection does not depend on the input order (the
//    density sums, and so the weights, agree to rounding; the octree builder
//    hands each node its points in an order fixed by their values, so its
//    results agree exactly). The level must enter the hash: a parent's
//    population is its children's kept points, and a subsampled child kept
//    its points *because* their u was small; drawing the same u again at the
//    parent would favour them, and the parent's points in the octant of a
//    child that kept everything came out at about half that child's mass
//    (measured on clustered data: median -47%, worst -89%). With a fresh u per
//    level each node is a priority sample of its population, and the
//    estimates below stay unbiased level after level
//    (SubtreeBuilder.ParentOctantsEstimateTheirChildsMassWithoutBias).
//    The priority is
//    q_i = s_i / u_i. The n largest priorities are kept; tau is the (n+1)-th
//    largest. For a kept point, max(s_i, tau) is an unbiased estimate of s_i
//    (shown in DLT: E[s^_i] = s_i with s^_i = 0 for points not kept), so
//
//       w^_i = w_i * max(1, tau / s_i)
//
//    is an unbiased estimate of w_i, and the sum of w^_i over the kept points
//    in any region is an unbiased estimate of the population's mass there,
//    whatever the importances: they only move the variance, which is lowest
//    where s_i is proportional to what is being estimated.
//
// 4. Exact total. The kept weights are scaled by (population weight /
//    sum of w^_i), so they sum exactly (to rounding) to the node's subtree
//    mass. This makes the estimator a ratio estimator: its bias is O(1/n) of
//    the region's mass, and in exchange every node of the tree carries the
//    same total mass as its subtree. The bias is largest where the heavy part
//    of a node gets few samples: measured on a half-clump, half-background
//    node with alpha = 1, a region inside the clump came out 6.6% light at
//    n = 300 and 2.2% light at n = 1000 (the raw w^_i, kept in
//    Sample::estimate, were within 0.3% +- 1.4%). At alpha <= 0.5 the same
//    test (n = 300, 200 seeds, tests/index/sampler_test.cc) shows no bias
//    beyond its noise; it shrinks as 1/n.
//
// 5. Smoothing length. A kept point stands for a volume W_i / rho_i (W_i its
//    new weight), and h_i = eta * (W_i / rho_i)^(1/3) with
//    eta = 2 * (3 / (4 pi))^(1/3) ~= 1.2407: the diameter of a sphere of that
//    volume, which makes a compact kernel of radius h overlap its
//    neighbours. h is clamped to [node size / 2^16, node size]. Leaf points
//    (all kept) get h the same way from their own mass (LeafSmoothingLengths).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "index/cube.h"
#include "index/morton.h"

namespace octocosm {

struct SamplerOptions {
  double alpha = 0.5;         // density exponent, >= 0
  int density_grid_bits = 5;  // fine density grid: 2^bits cells per axis, 1..8
  std::uint64_t seed = 0;     // changes every u_i; the same seed reproduces a run
};

// eta in h = eta * (W / rho)^(1/3).
inline constexpr double kSmoothingEta = 1.2407009817988;  // 2 * (3 / (4 pi))^(1/3)

struct Sample {
  std::vector<std::uint32_t> kept;  // indices into the population, ascending
  std::vector<double> weight;       // new weight of each kept point; they sum to the population's weight
  std::vector<double> estimate;     // the unbiased w^_i of step 3, before the rescaling of step 4
  std::vector<double> smoothing;    // smoothing length of each kept point
  double threshold = 0;             // tau; 0 when every point was kept
};

// Keeps min(capacity, population) points of the population of node `key`.
// position: 3 * m absolute coordinates, each inside the node cube; weight: m
// values > 0; sampling_id: m values (particle IDs, or SamplingId for inputs
// without IDs). When m <= capacity every point is kept with its own weight.
// Throws Error::InvalidArgument on mismatched lengths, capacity 0 or options
// out of range.
Sample SampleNode(std::span<const double> position, std::span<const double> weight,
                  std::span<const std::uint64_t> sampling_id, NodeKey key, const Cube& cube, std::size_t capacity,
                  const SamplerOptions& options);

// The same, for points given by their Cube::FinestGridCoords instead of
// their positions (the octree builder's form: no point is placed twice).
Sample SampleNode(std::span<const GridPoint> grid, std::span<const double> weight,
                  std::span<const std::uint64_t> sampling_id, NodeKey key, const Cube& cube, std::size_t capacity,
                  const SamplerOptions& options);

// Smoothing lengths for points that are all kept (a leaf): step 5 above with
// W_i = w_i. By position or by grid point.
std::vector<double> LeafSmoothingLengths(std::span<const double> position, std::span<const double> weight,
                                         NodeKey key, const Cube& cube, const SamplerOptions& options);
std::vector<double> LeafSmoothingLengths(std::span<const GridPoint> grid, std::span<const double> weight, NodeKey key,
                                         const Cube& cube, const SamplerOptions& options);

// Step 5 for one point: the smoothing length of a point of weight W whose
// fine density cell (edge cell_edge) holds population weight cell_weight, in
// a node of edge node_size.
double SmoothingLengthFor(double weight, double cell_weight, double cell_edge, double node_size);

// The index of the point's fine density cell inside node `key`
// (x | y << bits | z << 2 bits, each coordinate in [0, 2^bits)): step 1's grid.
std::uint32_t DensityCellIndex(const double* position, NodeKey key, const Cube& cube, int bits);

// A stand-in particle ID for inputs without IDs: a hash of the position's
// bits, so it is the same wherever and in whatever order the point is seen.
std::uint64_t SamplingId(const double* position);

// The u_i of a sampling ID and a seed: uniform in (0, 1], never 0.
double PriorityUniform(std::uint64_t sampling_id, std::uint64_t seed);
// The seed of the draws at one level of the tree (step 3).
std::uint64_t LevelSeed(std::uint64_t seed, int level);

}  // namespace octocosm
