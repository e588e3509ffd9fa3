// The level-of-detail frontier of a frame (query/lod_frontier.h) on trees
// built in memory: a frontier, within its budget, coarse before fine.
#include <gtest/gtest.h>

#include <algorithm>

#include <random>
#include <set>

#include "base/error.h"
#include "query/lod_frontier.h"
#include "query/view_culler.h"

namespace octocosm {
namespace {

// A random tree over the unit cube: inner nodes hold `capacity` points,
// leaves fewer; each node below `depth` has each child with probability p.
NodeHierarchy RandomTree(std::uint64_t seed, int depth, double p, std::uint64_t capacity = 1000) {
  std::mt19937_64 rng(seed);
  std::bernoulli_distribution keep(p);
  std::uniform_int_distribution<std::uint64_t> leaf_points(1, capacity);
  std::vector<IndexEntry> entries;
  std::vector<NodeKey> frontier = {NodeKey::Root()};
  while (!frontier.empty()) {
    const NodeKey key = frontier.back();
    frontier.pop_back();
    bool has_child = false;
    if (key.level() < depth) {
      for (int o = 0; o < 8; ++o) {
        if (keep(rng)) {
          frontier.push_back(key.Child(o));
          has_child = true;
        }
      }
    }
    entries.push_back({key.value(), 1, 100, has_child ? capacity : leaf_points(rng), 0, 1});
  }
  return NodeHierarchy::FromEntries(entries, "test");
}

ScreenErrorView ViewFrom(const std::array<double, 3>& position, double threshold) {
  Camera camera;
  camera.position = position;
  camera.look_at = {0.5, 0.5, 0.5};
  camera.near = 1e-4;
  camera.far = 100;
  return {camera, 720, threshold};
}

bool IsAncestor(const NodeHierarchy& h, std::int32_t a, std::int32_t b) {
  for (std::int32_t n = h.node(b).parent; n >= 0; n = h.node(n).parent) {
    if (n == a) return true;
  }
  return false;
}

TEST(LodFrontierTest, SelectionIsAFrontierCoveringEveryLeafInViewOnce) {
  const NodeHierarchy h = RandomTree(1, 5, 0.6);
  const Cube cube{{0, 0, 0}, 1, false};
  const ScreenErrorView view = ViewFrom({0.5, 0.5, 2.5}, 1e-9);  // refine everything
  const LodFrontier f = SelectLodFrontier(h, cube, view, {view.threshold_pixels, 0, 0});
  std::set<std::int32_t> selected(f.selected.begin(), f.selected.end());
  ASSERT_EQ(selected.size(), f.selected.size());
  std::uint64_t points = 0;
  for (std::int32_t s : f.selected) {
    points += h.node(s).entry.point_count;
    EXPECT_TRUE(h.node(s).is_leaf());  // a tiny threshold reaches the leaves
    for (std::int32_t t : f.selected) EXPECT_FALSE(IsAncestor(h, s, t));
  }
  EXPECT_EQ(points, f.points);
  // The whole cube is in view: every leaf is selected.
  EXPECT_EQ(f.points, h.total_points_in_leaves());
}

TEST(LodFrontierTest, SmallerThresholdsRefineMore) {
  const NodeHierarchy h = RandomTree(2, 6, 0.5);
  const Cube cube{{0, 0, 0}, 1, false};
  std::uint64_t last_points = 0;
  std::set<std::int32_t> last_refined;
  for (double threshold : {64.0, 16.0, 4.0, 1.0, 0.25}) {
    const ScreenErrorView view = ViewFrom({0.2, 0.4, 1.7}, threshold);
    const LodFrontier f = SelectLodFrontier(h, cube, view, {threshold, 0, 0});
    std::set<std::int32_t> refined(f.refined.begin(), f.refined.end());
    EXPECT_TRUE(std::includes(refined.begin(), refined.end(), last_refined.begin(), last_refined.end()));
    EXPECT_GE(f.points, last_points);
    last_points = f.points;
    last_refined = refined;
  }
  EXPECT_GT(last_refined.size(), 10u);
}

TEST(LodFrontierTest, PointBudgetIsNeverExceededAndSpentCoarseFirst) {
  const NodeHierarchy h = RandomTree(3, 6, 0.6);
  const Cube cube{{0, 0, 0}, 1, false};
  const ScreenErrorView view = ViewFrom({0.5, 0.5, 1.8}, 0.01);
  for (std::uint64_t budget : {1000u, 5000u, 20000u, 100000u}) {
    const LodFrontier f = SelectLodFrontier(h, cube, view, {0.01, budget, 0});
    EXPECT_LE(f.points, budget);
    EXPECT_TRUE(f.budget_reached);
    // Coarse before fine: a node is taken after its parent.
    std::set<std::int32_t> seen;
    for (std::int32_t n : f.load_order) {
      if (n != 0) {
        EXPECT_TRUE(seen.count(h.node(n).parent)) << "node " << h.node(n).key.Path();
      }
      seen.insert(n);
    }
  }
  // Without a budget the same view takes more.
  EXPECT_GT(SelectLodFrontier(h, cube, view, {0.01, 0, 0}).points, 100000u);
}

// A node whose children would overflow the budget is drawn as it is, and
// the budget left goes to a node further down the queue whose children fit.
TEST(LodFrontierTest, TheBudgetLeftAfterANodeTooCostlyToRefineGoesToTheNextThatFits) {
  const NodeKey root = NodeKey::Root(), near = root.Child(0), far = root.Child(7);
  std::vector<IndexEntry> entries = {{root.value(), 1, 1, 10, 0, 1}, {near.value(), 1, 1, 20, 0, 1},
                                     {far.value(), 1, 1, 10, 0, 1}};
  for (int o = 0; o < 8; ++o) {
    entries.push_back({near.Child(o).value(), 1, 1, 100, 0, 1});  // refining `near`: +780 points
    entries.push_back({far.Child(o).value(), 1, 1, 2, 0, 1});     // refining `far`: +6 points
  }
  const NodeHierarchy h = NodeHierarchy::FromEntries(entries, "test");
  const Cube cube{{0, 0, 0}, 1, false};
  const ScreenErrorView view = ViewFrom({-0.6, -0.6, -0.6}, 0.01);  // nearer `near`: its error comes first
  const LodFrontier f = SelectLodFrontier(h, cube, view, {0.01, 150, 0});
  EXPECT_TRUE(f.budget_reached);
  EXPECT_EQ(f.points, 20u + 16u);  // `near` as it is, `far` as its eight children
  const auto find = [&](NodeKey key) { return *h.Find(key); };
  EXPECT_NE(std::find(f.selected.begin(), f.selected.end(), find(near)), f.selected.end());
  EXPECT_NE(std::find(f.refined.begin(), f.refined.end(), find(far)), f.refined.end());
  EXPECT_LT(std::find(f.load_order.begin(), f.load_order.end(), find(near)),
            std::find(f.load_order.begin(), f.load_order.end(), find(far)));
}

TEST(LodFrontierTest, NodesOutOfViewAreCulled) {
  const NodeHierarchy h = RandomTree(4, 4, 0.7);
  const Cube cube{{0, 0, 0}, 1, false};
  ScreenErrorView away = ViewFrom({0.5, 0.5, 3}, 1);
  away.camera.look_at = {0.5, 0.5, 6};  // looking away from the cube
  const LodFrontier none = SelectLodFrontier(h, cube, away, {1, 0, 0});
  EXPECT_TRUE(none.selected.empty());
  EXPECT_EQ(none.points, 0u);
  // Inside the cube, looking at one corner: some children culled.
  ScreenErrorView inside = ViewFrom({0.5, 0.5, 0.5}, 0.5);
  inside.camera.look_at = {0.9, 0.9, 0.9};
  const LodFrontier part = SelectLodFrontier(h, cube, inside, {0.5, 0, 0});
  EXPECT_GT(part.nodes_culled, 0u);
  EXPECT_LT(part.points, h.total_points_in_leaves());
}

// Each octant's bit is the test of that octant's cube grown by its reach.
TEST(ViewCullerTest, OctantsInViewAreEachOctantsOwnTest) {
  Camera camera;
  camera.position = {0.5, 0.5, 0.5};
  camera.look_at = {0.9, 0.8, 0.7};
  camera.near = 1e-4;
  camera.far = 100;
  std::mt19937_64 random(3);
  std::uniform_real_distribution<double> where(-0.5, 1.5), size(0.01, 0.5), reach(0, 0.1);
  for (const bool periodic : {false, true}) {
    const Cube cube{{0, 0, 0}, 1, periodic};
    const ViewCuller culler(camera, cube, periodic ? 0.02 : 0);
    int partial = 0;
    for (int trial = 0; trial < 5000; ++trial) {
      const NodeCube c{{where(random), where(random), where(random)}, size(random)};
      std::array<double, 8> reaches{};
      for (double& r : reaches) r = trial % 2 ? reach(random) : 0;
      std::uint8_t want = 0;
      for (int o = 0; o < 8; ++o) {
        const double half = c.size / 2;
        const NodeCube octant{{c.origin[0] + (o & 1) * half, c.origin[1] + ((o >> 1) & 1) * half,
                               c.origin[2] + ((o >> 2) & 1) * half},
                              half};
        if (culler.MayMeet(octant, reaches[static_cast<std::size_t>(o)])) want |= static_cast<std::uint8_t>(1u << o);
      }
      ASSERT_EQ(culler.OctantsInView(c, reaches), want) << trial;
      partial += want != 0 && want != 0xFF;
    }
    EXPECT_GT(partial, 100);
  }
  const std::array<double, 8> none{};
  EXPECT_EQ(ViewCuller().OctantsInView({{5, 5, 5}, 1}, none), 0xFF) << "no view: everything is seen";
}

// A blob reaching into the view keeps its octant. A 90-degree view along -z
// sees x <= depth; octants whose nearest corner has x + z = d lie d / sqrt(2)
// beside it and are kept once grown by d / 2 on every axis.
TEST(ViewCullerTest, AReachIntoTheViewKeepsTheOctant) {
  Camera camera;
  camera.position = {0, 0, 0};
  camera.look_at = {0, 0, -1};
  camera.fov_y_degrees = 90;
  camera.aspect = 1;
  camera.near = 0.1;
  camera.far = 100;
  const ViewCuller culler(camera, Cube{{-100, -100, -100}, 200, false}, 0);
  // Octants 0 and 2 (low x, low z): d = 0.5; 1, 3, 4, 6: d = 1.5; 5, 7: 2.5.
  const NodeCube beside{{8.5, -1, -8}, 2};
  std::array<double, 8> reach{};
  EXPECT_EQ(culler.OctantsInView(beside, reach), 0);
  reach.fill(0.2);
  EXPECT_EQ(culler.OctantsInView(beside, reach), 0);
  reach.fill(0.3);
  EXPECT_EQ(culler.OctantsInView(beside, reach), 0b00000101);
  reach.fill(0.8);
  EXPECT_EQ(culler.OctantsInView(beside, reach), 0b01011111);
  reach.fill(1.3);
  EXPECT_EQ(culler.OctantsInView(beside, reach), 0xFF);
  reach = {0, 0, 0, 0, 0, 0, 0, 1.3};  // each octant by its own reach
  EXPECT_EQ(culler.OctantsInView(beside, reach), 0b10000000);
}

// In a periodic cube, points that interpolation moves past the upper x face
// are drawn near the lower one: a camera that sees only a thin slab inside
// the lower face must keep the nodes at the upper face that the margin
// reaches across it, and only then.
TEST(LodFrontierTest, PeriodicMarginReachesAcrossTheBox) {
  const NodeHierarchy h = RandomTree(6, 4, 1.0);
  ScreenErrorView view = ViewFrom({0.05, 0.5, 0.5}, 1e-9);
  view.camera.look_at = {0, 0.5, 0.5};
  view.camera.far = 0.04;  // sees 0.01 <= x <= 0.05
  const auto at_upper_face = [&](const LodFrontier& f, const Cube& cube) {
    int n = 0;
    for (std::int32_t s : f.selected) {
      const NodeCube c = cube.NodeCubeOf(h.node(s).key);
      n += c.origin[0] + c.size == 1;
    }
    return n;
  };
  const Cube periodic{{0, 0, 0}, 1, true};
  const Cube bounded{{0, 0, 0}, 1, false};
  EXPECT_GT(at_upper_face(SelectLodFrontier(h, periodic, view, {1e-9, 0, 0.05}), periodic), 0);
  EXPECT_EQ(at_upper_face(SelectLodFrontier(h, bounded, view, {1e-9, 0, 0.05}), bounded), 0);
  EXPECT_EQ(at_upper_face(SelectLodFrontier(h, periodic, view, {1e-9, 0, 0}), periodic), 0);
  // A margin that stops short of the slab (the images reach x = 0.005) keeps none.
  EXPECT_EQ(at_upper_face(SelectLodFrontier(h, periodic, view, {1e-9, 0, 0.005}), periodic), 0);
}

TEST(LodFrontierTest, BadOptionsAreRejected) {
  const NodeHierarchy h = RandomTree(5, 2, 0.5);
  const Cube cube{{0, 0, 0}, 1, false};
  EXPECT_THROW(SelectLodFrontier(h, cube, ViewFrom({0, 0, 3}, 1), {0, 0, 0}), Error);
  EXPECT_THROW(SelectLodFrontier(h, cube, ViewFrom({0, 0, 3}, 1), {1, 0, -1}), Error);
}

TEST(NodeHierarchyTest, AnOrphanNodeIsCorruption) {
  std::vector<IndexEntry> entries = {{NodeKey::Root().value(), 1, 1, 5, 0, 1},
                                     {NodeKey::Root().Child(3).Child(1).value(), 1, 1, 5, 0, 1}};
  EXPECT_THROW(NodeHierarchy::FromEntries(entries, "test"), Error);
  entries[1].key = NodeKey::Root().Child(3).value();
  const NodeHierarchy h = NodeHierarchy::FromEntries(entries, "test");
  EXPECT_EQ(h.node(0).children[3], 1);
  EXPECT_EQ(h.Find(NodeKey::Root().Child(3)), 1);
  EXPECT_FALSE(h.Find(NodeKey::Root().Child(2)).has_value());
  EXPECT_EQ(h.total_points_in_leaves(), 5u);
}

}  // namespace
}  // namespace octocosm
