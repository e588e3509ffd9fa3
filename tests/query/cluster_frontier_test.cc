// The cluster-by-cluster frontier (query/cluster_frontier.h) on trees built
// in memory, with octant bounds made up for them.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>

#include "base/error.h"
#include "query/cluster_frontier.h"

namespace octocosm {
namespace {

// A full tree of `depth` levels below the root over the unit cube, every
// node holding 100 points.
NodeHierarchy FullTree(int depth) {
  std::vector<IndexEntry> entries;
  std::vector<NodeKey> frontier = {NodeKey::Root()};
  while (!frontier.empty()) {
    const NodeKey key = frontier.back();
    frontier.pop_back();
    if (key.level() < depth) {
      for (int o = 0; o < 8; ++o) frontier.push_back(key.Child(o));
    }
    entries.push_back({key.value(), 1, 100, 100, 0, 1});
  }
  return NodeHierarchy::FromEntries(entries, "test");
}

Camera LookingAtTheCube(const std::array<double, 3>& position) {
  Camera c;
  c.position = position;
  c.look_at = {0.5, 0.5, 0.5};
  c.near = 1e-4;
  c.far = 100;
  return c;
}

// Each octant's sphere about its cube's centre, of the octant's half
// diagonal, with bounds that shrink by `shrink` a level (as a store's do).
OctantRefineBounds BoundsOf(const NodeCube& node, double shrink) {
  OctantRefineBounds b;
  for (int o = 0; o < 8; ++o) {
    OctantRefineBound& octant = b[static_cast<std::size_t>(o)];
    for (int a = 0; a < 3; ++a) {
      octant.centre[static_cast<std::size_t>(a)] = node.origin[static_cast<std::size_t>(a)] + node.size * (((o >> a) & 1) ? 0.75 : 0.25);
    }
    octant.radius = node.size * std::sqrt(3.0) / 4;
    octant.mass = node.size * node.size * node.size * shrink;
    octant.mass_variance = octant.mass * node.size * node.size;
  }
  return b;
}

// A full tree of 3 levels over the unit cube, every inner node loaded with
// its octants' bounds.
struct BoundedTree {
  BoundedTree() : hierarchy(FullTree(3)), bounds(hierarchy.nodes().size()) {
    for (std::size_t n = 0; n < bounds.size(); ++n) bounds[n].octants = BoundsOf(cube.NodeCubeOf(hierarchy.nodes()[n].key), 1);
  }
  const NodeRefineBounds* Loaded(std::int32_t n) const {
    return hierarchy.node(n).is_leaf() ? nullptr : &bounds[static_cast<std::size_t>(n)];
  }
  NodeHierarchy hierarchy;
  Cube cube{{0, 0, 0}, 1, false};
  std::vector<NodeRefineBounds> bounds;  // the octants' bounds alone
};

// E = s / sqrt(1 + s / r), s = a / (q D^2), of any cluster inside the
// octant's sphere (its own sphere inside it, its bounds at most the
// octant's) is at most the bound.
TEST(ClusterFrontierTest, TheOctantBoundHoldsEveryClusterInside) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(0, 1);
  const double q = std::pow(0.5 / 600, 2);
  for (int trial = 0; trial < 2000; ++trial) {
    OctantRefineBound bound;
    bound.centre = {unit(rng), unit(rng), unit(rng)};
    bound.radius = 0.2 * unit(rng);
    bound.mass = unit(rng);
    bound.mass_variance = unit(rng) * 1e-3;
    const std::array<double, 3> camera = {3 * unit(rng) - 1, 3 * unit(rng) - 1, 3 * unit(rng) - 1};
    // A cluster: its own sphere (R) inside the octant's.
    const double R = bound.radius * unit(rng);
    std::array<double, 3> x;
    double norm = 0;
    for (double& v : x) {
      v = unit(rng) - 0.5;
      norm += v * v;
    }
    const double along = (bound.radius - R) * unit(rng) / std::sqrt(norm);
    double distance2 = 0;
    for (std::size_t a = 0; a < 3; ++a) {
      x[a] = bound.centre[a] + along * x[a];
      distance2 += (x[a] - camera[a]) * (x[a] - camera[a]);
    }
    const double a = bound.mass_variance * unit(rng), r = bound.mass * unit(rng);
    const double gap = std::max(0.0, std::sqrt(distance2) - R);
    const double spread = a / (q * gap * gap);
    const double error = gap > 0 ? spread / std::sqrt(1 + spread / r) : INFINITY;
    EXPECT_LE(error, LargestClusterError(bound, camera, q) * (1 + 1e-12));
  }
  EXPECT_EQ(LargestClusterError(OctantRefineBound{}, {0, 0, 0}, q), 0) << "an octant without clusters";
}

// Nodes are reached through loaded parents only, parents before children,
// where the bound exceeds the threshold: the root alone at a threshold above
// every bound, every node at threshold 0, fewer the higher it is.
TEST(ClusterFrontierTest, ReachesThroughLoadedParentsWhereTheBoundExceedsTheThreshold) {
  const BoundedTree tree;
  const NodeHierarchy& h = tree.hierarchy;
  const Cube& cube = tree.cube;
  const std::vector<NodeRefineBounds>& bounds = tree.bounds;
  const auto all_loaded = [&](std::int32_t n) { return tree.Loaded(n); };
  ClusterLodOptions o;
  o.focal_pixels = 600;
  const Camera camera = LookingAtTheCube({0.4, 0.5, -2});  // the whole cube in view
  o.threshold = 0;
  LodFrontier everything = SelectClusterFrontier(h, cube, camera, o, all_loaded);
  EXPECT_EQ(everything.selected.size(), h.nodes().size());
  std::set<std::int32_t> seen;
  for (std::int32_t n : everything.selected) {
    if (h.node(n).parent >= 0) {
      EXPECT_TRUE(seen.count(h.node(n).parent)) << "parents come first";
    }
    seen.insert(n);
  }
  EXPECT_EQ(everything.points, 100 * h.nodes().size());

  o.threshold = 1e9;
  EXPECT_EQ(SelectClusterFrontier(h, cube, camera, o, all_loaded).selected.size(), 1u) << "the root alone";

  // Only the root loaded: its children are reached, nothing below them.
  const auto root_loaded = [&](std::int32_t n) -> const NodeRefineBounds* { return n == 0 ? &bounds[0] : nullptr; };
  o.threshold = 0;
  EXPECT_EQ(SelectClusterFrontier(h, cube, camera, o, root_loaded).selected.size(), 9u);

  // Between: fewer nodes the higher the threshold, each reached where its
  // parent's bound exceeds the threshold.
  std::size_t previous = h.nodes().size() + 1;
  for (const double threshold : {0.1, 1.0, 5.0, 50.0, 300.0}) {
    o.threshold = threshold;
    const LodFrontier f = SelectClusterFrontier(h, cube, camera, o, all_loaded);
    EXPECT_LE(f.selected.size(), previous);
    previous = f.selected.size();
    for (std::int32_t n : f.selected) {
      const std::int32_t parent = h.node(n).parent;
      if (parent < 0) continue;
      const int octant = static_cast<int>(h.node(n).key.value() & 7);
      const double q = std::pow(0.5 / o.focal_pixels, 2);
      EXPECT_GT(LargestClusterError(bounds[static_cast<std::size_t>(parent)].octants[static_cast<std::size_t>(octant)],
                                    camera.position, q) * (1 + 1e-4), threshold);
    }
  }
  EXPECT_LT(previous, h.nodes().size());
  EXPECT_GT(previous, 1u);
}

// A node's clusters in its child octants, each in its octant's cube with a
// small sphere of its own, bounds spread over decades (a few heavy ones).
struct ClusteredNode {
  explicit ClusteredNode(std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> unit(0, 1);
    for (std::uint32_t o = 0; o < 8; ++o) {
      octant_first[o] = static_cast<std::uint32_t>(clusters.size());
      const std::size_t count = o == 5 ? 0 : 50 + rng() % 400;  // octant 5 holds none
      for (std::size_t i = 0; i < count; ++i) {
        OctantRefineBound c;
        for (std::size_t a = 0; a < 3; ++a) c.centre[a] = 0.5 * (((o >> a) & 1) + unit(rng));
        c.radius = 0.01 * unit(rng);
        c.mass = std::pow(10.0, -3 * unit(rng));
        c.mass_variance = c.mass * 1e-4 * std::pow(10.0, -2 * unit(rng));
        clusters.push_back(c);
      }
    }
    octant_first[8] = static_cast<std::uint32_t>(clusters.size());
    bounds = NodeRefineBounds::Of(NodeCube{{0, 0, 0}, 1}, clusters, octant_first);
  }
  // The largest error of the clusters of octant o, one by one.
  double LargestError(std::uint32_t o, const std::array<double, 3>& camera, double q) const {
    double largest = 0;
    for (std::uint32_t i = octant_first[o]; i < octant_first[o + 1]; ++i) {
      largest = std::max(largest, LargestClusterError(clusters[i], camera, q));
    }
    return largest;
  }
  std::vector<OctantRefineBound> clusters;
  std::array<std::uint32_t, 9> octant_first{};
  NodeRefineBounds bounds;
};

// With each cluster's bounds, a child is reached exactly where one of its
// octant's clusters may exceed the threshold, however the heaviest and the
// nearest lie; the octants' bounds alone reach more.
TEST(ClusterFrontierTest, ReachesAChildExactlyWhereOneOfItsClustersNeedsIt) {
  const NodeHierarchy h = FullTree(1);
  const Cube cube{{0, 0, 0}, 1, false};
  std::size_t exact_reached = 0, octants_reached = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    const ClusteredNode node(seed);
    NodeRefineBounds octants_alone;
    octants_alone.octants = node.bounds.octants;
    for (std::uint32_t o = 0; o < 8; ++o) {
      const std::size_t members = node.octant_first[o + 1] - node.octant_first[o];
      EXPECT_EQ(node.bounds.trees[o].empty() ? 0 : node.bounds.trees[o][0].size(), members);
    }
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> unit(0, 1);
    // The whole cube in view, from near and far.
    const Camera camera = LookingAtTheCube({unit(rng), unit(rng), -2 - 3 * unit(rng)});
    ClusterLodOptions o;
    o.focal_pixels = 600;
    const double q = std::pow(0.5 / o.focal_pixels, 2);
    for (const double threshold : {0.03, 0.1, 0.3, 1.0, 3.0}) {
      o.threshold = threshold;
      const LodFrontier exact = SelectClusterFrontier(h, cube, camera, o, [&](std::int32_t n) {
        return n == 0 ? &node.bounds : nullptr;
      });
      const LodFrontier coarse = SelectClusterFrontier(h, cube, camera, o, [&](std::int32_t n) {
        return n == 0 ? &octants_alone : nullptr;
      });
      std::set<std::int32_t> expected = {0};
      for (std::uint32_t octant = 0; octant < 8; ++octant) {
        if (node.LargestError(octant, camera.position, q) * (1 + 1e-4) > threshold) {
          expected.insert(h.node(0).children[octant]);
        }
      }
      ASSERT_EQ(exact.nodes_culled, 0u);
      EXPECT_EQ(std::set<std::int32_t>(exact.selected.begin(), exact.selected.end()), expected)
          << "seed " << seed << ", threshold " << threshold;
      EXPECT_LE(exact.selected.size(), coarse.selected.size());
      exact_reached += exact.selected.size();
      octants_reached += coarse.selected.size();
    }
  }
  EXPECT_LT(exact_reached, octants_reached) << "the octants' bounds alone reach children no cluster needs";
}

// Out of view, nothing is reached; within the budget, the points of the
// nodes reached stay within it.
TEST(ClusterFrontierTest, CullsAndKeepsTheBudget) {
  const BoundedTree tree;
  const NodeHierarchy& h = tree.hierarchy;
  const Cube& cube = tree.cube;
  const auto loaded = [&](std::int32_t n) { return tree.Loaded(n); };
  ClusterLodOptions o;
  o.focal_pixels = 600;
  Camera away = LookingAtTheCube({0.5, 0.5, -1});
  away.look_at = {0.5, 0.5, -2};
  EXPECT_TRUE(SelectClusterFrontier(h, cube, away, o, loaded).selected.empty());

  // Inside, looking along +x: the nodes behind the camera are culled.
  Camera inside = LookingAtTheCube({0.05, 0.5, 0.5});
  inside.look_at = {1, 0.5, 0.5};
  const LodFrontier f = SelectClusterFrontier(h, cube, inside, o, loaded);
  EXPECT_GT(f.nodes_culled, 0u);
  EXPECT_LT(f.selected.size(), h.nodes().size());

  o.point_budget = 1000;
  const LodFrontier budgeted = SelectClusterFrontier(h, cube, LookingAtTheCube({0.5, 0.5, -1}), o, loaded);
  EXPECT_TRUE(budgeted.budget_reached);
  EXPECT_LE(budgeted.points, 1000u);
  EXPECT_EQ(budgeted.points, 100 * budgeted.selected.size());

  o.threshold = -1;
  EXPECT_THROW(SelectClusterFrontier(h, cube, inside, o, loaded), Error);
  o.threshold = 0;
  o.focal_pixels = 0;
  EXPECT_THROW(SelectClusterFrontier(h, cube, inside, o, loaded), Error);
}

}  // namespace
}  // namespace octocosm
