// Draw plans while blocks arrive (render/draw_plan.h): parents stand in for
// children not loaded yet, with no holes where an ancestor is loaded and no
// region drawn twice.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>

#include "render/draw_plan.h"

namespace octocosm {
namespace {

NodeHierarchy FullTree(int depth) {
  std::vector<IndexEntry> entries;
  std::vector<NodeKey> todo = {NodeKey::Root()};
  while (!todo.empty()) {
    const NodeKey key = todo.back();
    todo.pop_back();
    entries.push_back({key.value(), 1, 1, 800, 0, 1});
    if (key.level() < depth) {
      for (int o = 0; o < 8; ++o) todo.push_back(key.Child(o));
    }
  }
  return NodeHierarchy::FromEntries(entries, "test");
}

// Each node's 800 points: 100 per octant.
std::array<std::uint32_t, 9> Offsets(std::int32_t) {
  std::array<std::uint32_t, 9> o{};
  for (int k = 0; k <= 8; ++k) o[k] = static_cast<std::uint32_t>(100 * k);
  return o;
}

LodFrontier FrontierOf(const NodeHierarchy& h, std::mt19937_64& rng) {
  // A random frontier: refine each node with probability 0.6 (children
  // sometimes out of view), as SelectLodFrontier would produce.
  LodFrontier f;
  std::bernoulli_distribution refine(0.6), in_view(0.85);
  std::vector<std::int32_t> todo = {0};
  while (!todo.empty()) {
    const std::int32_t n = todo.back();
    todo.pop_back();
    if (!h.node(n).is_leaf() && refine(rng)) {
      f.refined.push_back(n);
      for (std::int32_t c : h.node(n).children) {
        if (c >= 0 && in_view(rng)) todo.push_back(c);
      }
    } else {
      f.selected.push_back(n);
      f.points += h.node(n).entry.point_count;
    }
  }
  return f;
}

TEST(DrawPlanTest, EverythingLoadedDrawsExactlyTheSelection) {
  const NodeHierarchy h = FullTree(3);
  std::mt19937_64 rng(1);
  const LodFrontier f = FrontierOf(h, rng);
  const DrawPlan plan = PlanDraws(h, f, [](std::int32_t) { return true; }, Offsets);
  EXPECT_EQ(plan.points, f.points);
  EXPECT_EQ(plan.stand_ins, 0u);
  EXPECT_EQ(plan.ranges.size(), f.selected.size());
}

TEST(DrawPlanTest, SelectedNodesDrawOnlyTheirOctantsInView) {
  const NodeHierarchy h = FullTree(3);
  std::mt19937_64 rng(3);
  const LodFrontier f = FrontierOf(h, rng);
  std::vector<std::uint8_t> octants(h.nodes().size());
  std::uint64_t want = 0;
  for (std::size_t i = 0; i < f.selected.size(); ++i) {
    const auto in_view = static_cast<std::uint8_t>(i % 3 == 0 ? 0xFF : rng() | 1);
    octants[static_cast<std::size_t>(f.selected[i])] = in_view;
    want += 100 * static_cast<std::uint64_t>(__builtin_popcount(in_view));
  }
  const DrawPlan plan = PlanDraws(h, f, [](std::int32_t) { return true; }, Offsets,
                                  [&](std::int32_t n) { return octants[static_cast<std::size_t>(n)]; });
  EXPECT_EQ(plan.points, want);
  for (const DrawRange& r : plan.ranges) {
    ASSERT_NE(std::find(f.selected.begin(), f.selected.end(), r.node), f.selected.end());
    for (std::uint32_t o = r.first / 100; o < (r.first + r.count) / 100; ++o) {
      EXPECT_TRUE((octants[static_cast<std::size_t>(r.node)] >> o) & 1) << "octant " << o << " is out of view";
    }
  }
}

TEST(DrawPlanTest, ParentsStandInForMissingChildrenWithoutHolesOrOverlap) {
  const NodeHierarchy h = FullTree(3);
  std::mt19937_64 rng(2);
  for (int trial = 0; trial < 300; ++trial) {
    const LodFrontier f = FrontierOf(h, rng);
    std::bernoulli_distribution is_loaded(trial % 3 == 0 ? 0.2 : 0.6);
    std::vector<bool> loaded(h.nodes().size());
    for (std::size_t n = 0; n < loaded.size(); ++n) loaded[n] = is_loaded(rng);
    const DrawPlan plan = PlanDraws(h, f, [&](std::int32_t n) { return loaded[static_cast<std::size_t>(n)]; }, Offsets);

    // How many draws cover each selected node: a whole draw of the node, or
    // an octant range of an ancestor whose octant holds it.
    std::map<std::int32_t, int> cover;
    for (const DrawRange& r : plan.ranges) {
      ASSERT_TRUE(loaded[static_cast<std::size_t>(r.node)]);
      for (std::int32_t s : f.selected) {
        if (s == r.node) {
          ASSERT_EQ(r.first, 0u);
          ASSERT_EQ(r.count, h.node(s).entry.point_count);
          ++cover[s];
          continue;
        }
        // Is s below octant o of r.node for an o inside the range?
        std::int32_t below = s;
        while (below >= 0 && h.node(below).parent != r.node) below = h.node(below).parent;
        if (below < 0) continue;
        const auto o = static_cast<std::uint32_t>(h.node(below).key.OctantInParent());
        if (100 * o >= r.first && 100 * o < r.first + r.count) ++cover[s];
      }
    }
    for (std::int32_t s : f.selected) {
      bool reachable = false;  // a loaded node on the path from the root to s
      for (std::int32_t n = s; n >= 0; n = h.node(n).parent) reachable |= loaded[static_cast<std::size_t>(n)];
      ASSERT_EQ(cover[s], reachable ? 1 : 0) << "trial " << trial << ", node " << h.node(s).key.Path();
    }
  }
}

// The cluster cut's plan (PlanClusterDraws): every loaded node reached whose
// parent is drawn draws its octants, with the cut where the octant's child is
// drawn too and whatever their error where it is not; a node whose parent is
// not drawn is not drawn either.
TEST(DrawPlanTest, TheClusterCutDrawsReachedNodesWithTheirRoles) {
  const NodeHierarchy h = FullTree(2);
  const std::int32_t root = 0;
  const std::int32_t a = h.node(root).children[0], b = h.node(root).children[5];
  const std::int32_t a_child = h.node(a).children[2], b_child = h.node(b).children[7];
  LodFrontier f;
  f.selected = {root, a, b, a_child, b_child};
  // b is reached but not loaded: its octant of the root is final, and its
  // child, though loaded, is not drawn.
  const auto loaded = [&](std::int32_t n) { return n != b; };
  const DrawPlan plan = PlanClusterDraws(h, f, loaded, Offsets);
  std::map<std::pair<std::int32_t, std::uint32_t>, CutRole> roles;  // (node, first point) -> role
  std::uint64_t points = 0;
  for (const DrawRange& r : plan.ranges) {
    for (std::uint32_t first = r.first; first < r.first + r.count; first += 100) roles[{r.node, first}] = r.cut;
    points += r.count;
  }
  EXPECT_EQ(points, plan.points);
  EXPECT_EQ(points, 3u * 800) << "the root, a and a's child";
  EXPECT_EQ(roles.at({root, 0}), CutRole::kCut) << "a is drawn";
  EXPECT_EQ(roles.at({root, 500}), CutRole::kCutFinal) << "b is not loaded";
  EXPECT_EQ(roles.at({root, 300}), CutRole::kCutFinal) << "not reached";
  EXPECT_EQ(roles.at({a, 200}), CutRole::kCut);
  EXPECT_EQ(roles.at({a, 0}), CutRole::kCutFinal);
  EXPECT_EQ(roles.at({a_child, 0}), CutRole::kCutFinal) << "a leaf";
  EXPECT_FALSE(roles.count({b_child, 0})) << "its parent is not drawn";
  EXPECT_EQ(plan.stand_ins, 1u) << "the root's octant of b";
  // Adjacent octants of one role are one draw: the root's octant 0 (kCut),
  // then octants 1 to 7 (kCutFinal).
  EXPECT_EQ(std::count_if(plan.ranges.begin(), plan.ranges.end(), [&](const DrawRange& r) { return r.node == root; }), 2);
}

}  // namespace
}  // namespace octocosm
