// The level of detail that refines cluster by cluster (docs/FORMAT.md
// section 4): which nodes a renderer loads and draws so that its GPU can
// draw, of the store's cluster tree, the cut a threshold tau gives: every
// cluster whose error bound E (seen from the camera) is at most tau and
// whose parent's is above it. The GPU decides point by point; the CPU only
// finds the nodes where some point may be drawn.
//
// A node's clusters tell, once its block is loaded, how far below them the
// cut can reach: for each child octant, a sphere holding the spheres of the
// octant's clusters and the largest of their bounds (OctantRefineBound),
// and a tree of such spheres down to each cluster's (NodeRefineBounds).
// From a sphere the largest E any cluster inside may have follows (E grows
// with a and r and shrinks with the distance D), and the child is needed
// only where one of the octant's clusters may exceed tau. Starting from the root, nodes are
// reached in order of that bound (largest first) through loaded parents, so
// a frame reaches one level further for each level whose blocks have
// arrived; a renderer that waits for its blocks selects again until nothing
// new is reached.
//
// A child that is not reached, because it is out of view, not needed, not
// loaded yet or over the point budget, leaves its parent's clusters of that
// octant to be drawn whatever their error: the cut stays one, each
// particle's mass drawn once, and the frontier's bounds decide how fine the
// picture is, never whether it is whole.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "index/cube.h"
#include "index/node_hierarchy.h"
#include "query/frustum.h"
#include "query/lod_frontier.h"

namespace octocosm {

// What a node's clusters of one child octant are, at most: a sphere (world
// units) that holds every cluster's sphere of the octant, and the largest of
// their bounds a (mass times blob variance) and r (mass).
struct OctantRefineBound {
  std::array<double, 3> centre{};
  double radius = -1;  // < 0: the octant has no clusters
  double mass_variance = 0;
  double mass = 0;
};
using OctantRefineBounds = std::array<OctantRefineBound, 8>;

// What a loaded node's clusters tell the frontier: for each child octant, a
// tree of bounds over its clusters (QSplat's bounding spheres): level 0 each
// cluster's own sphere and bounds, ordered along a Morton curve; each entry
// of level k + 1 the bound of up to kFanOut consecutive entries of level k;
// the last level a few entries. Where an octant's bound exceeds the
// threshold the frontier descends it, so that a child is reached only where
// one of its clusters needs it, not wherever the heaviest cluster's bound
// meets the nearest one's distance. Without trees the octants' bounds alone
// decide.
struct NodeRefineBounds {
  static constexpr std::size_t kFanOut = 8;
  // A bound of the tree: its sphere's centre relative to the node's corner,
  // in floats, the radius grown and the bounds rounded up to hold what they
  // stand for (24 bytes a cluster instead of 48).
  struct Sphere {
    std::array<float, 3> centre{};
    float radius = -1;
    float mass_variance = 0;
    float mass = 0;
  };
  using Tree = std::vector<std::vector<Sphere>>;
  OctantRefineBounds octants;
  std::array<double, 3> corner{};  // the node's, world units
  std::array<Tree, 8> trees;

  // The bounds of a node's clusters, `clusters` each as its own bound (a
  // sphere about its position), the clusters of child octant o from
  // octant_first[o] to octant_first[o + 1] (clamped to the clusters).
  static NodeRefineBounds Of(const NodeCube& node, std::span<const OctantRefineBound> clusters,
                             const std::array<std::uint32_t, 9>& octant_first);
};

// The largest error E = s / sqrt(1 + s / r), s = a / (q D^2), that a cluster
// of the octant may have seen from `camera`, with q = (half a pixel / focal
// length)^2 (docs/FORMAT.md section 4): the bounds' a and r, and the
// distance D from the camera to the octant's sphere (infinite at 0).
double LargestClusterError(const OctantRefineBound& bound, const std::array<double, 3>& camera, double q);

struct ClusterLodOptions {
  double threshold = 0;            // tau (mass units, >= 0): 0 draws every particle
  double focal_pixels = 1;         // the view's focal length (pixels, > 0)
  std::uint64_t point_budget = 0;  // most points in the nodes reached; 0: no limit
  double cull_margin = 0;          // as LodOptions::cull_margin
};

// `bounds(node)`: the octant bounds of a loaded node whose points are
// clusters linked to its children's, or null (not loaded, a leaf, or a
// block without links). The frontier's `selected` lists every node reached,
// parents before children and in load order (as `load_order`); `refined`
// those with a child reached; `points` the points of the nodes reached.
// Throws Error::InvalidArgument for a threshold that is not finite and >= 0,
// a focal length that is not > 0, or a negative margin.
LodFrontier SelectClusterFrontier(const NodeHierarchy& hierarchy, const Cube& cube, const Camera& camera,
                                  const ClusterLodOptions& options,
                                  const std::function<const NodeRefineBounds*(std::int32_t)>& bounds);

}  // namespace octocosm
