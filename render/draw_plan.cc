#include "render/draw_plan.h"

#include <vector>

namespace octocosm {
namespace {

enum class Role : std::uint8_t { kNone, kSelected, kRefined };

class Planner {
 public:
  Planner(const NodeHierarchy& hierarchy, const std::function<bool(std::int32_t)>& loaded,
          const std::function<std::array<std::uint32_t, 9>(std::int32_t)>& octant_offsets,
          const std::function<std::uint8_t(std::int32_t)>& octants_in_view)
      : hierarchy_(hierarchy),
        loaded_(loaded),
        octant_offsets_(octant_offsets),
        octants_in_view_(octants_in_view),
        roles_(hierarchy.nodes().size(), Role::kNone),
        covered_(hierarchy.nodes().size(), kUnknown) {}

  void SetRole(std::int32_t node, Role role) { roles_[static_cast<std::size_t>(node)] = role; }

  void Draw(std::int32_t node, DrawPlan& plan) {
    const Role role = RoleOf(node);
    if (role == Role::kSelected) {
      if (!loaded_(node)) return;
      const std::uint8_t octants = octants_in_view_ ? octants_in_view_(node) : kEveryOctant;
      if (octants == kEveryOctant) {
        Add(plan, node, 0, static_cast<std::uint32_t>(hierarchy_.node(node).entry.point_count));
        return;
      }
      const std::array<std::uint32_t, 9> offsets = octant_offsets_(node);
      for (int o = 0; o < 8; ++o) {
        if (((octants >> o) & 1) && offsets[o + 1] > offsets[o]) Add(plan, node, offsets[o], offsets[o + 1] - offsets[o]);
      }
      return;
    }
    if (role != Role::kRefined) return;
    const bool self_loaded = loaded_(node);
    std::array<std::uint32_t, 9> offsets{};
    if (self_loaded) offsets = octant_offsets_(node);
    for (int o = 0; o < 8; ++o) {
      const std::int32_t child = hierarchy_.node(node).children[static_cast<std::size_t>(o)];
      if (child < 0 || RoleOf(child) == Role::kNone) continue;  // empty or out of view
      if (Covered(child) || !self_loaded) {
        Draw(child, plan);
      } else if (offsets[o + 1] > offsets[o]) {
        Add(plan, node, offsets[o], offsets[o + 1] - offsets[o]);
        ++plan.stand_ins;
      }
    }
  }

 private:
  Role RoleOf(std::int32_t node) const { return roles_[static_cast<std::size_t>(node)]; }

  bool Covered(std::int32_t node) {
    std::uint8_t& memo = covered_[static_cast<std::size_t>(node)];
    if (memo != kUnknown) return memo != 0;
    bool covered = loaded_(node);
    if (!covered && RoleOf(node) == Role::kRefined) {
      covered = true;
      for (std::int32_t child : hierarchy_.node(node).children) {
        if (child >= 0 && RoleOf(child) != Role::kNone && !Covered(child)) {
          covered = false;
          break;
        }
      }
    }
    memo = covered ? 1 : 0;
    return covered;
  }

  void Add(DrawPlan& plan, std::int32_t node, std::uint32_t first, std::uint32_t count) {
    // Adjacent octant ranges of one node become one draw.
    if (!plan.ranges.empty() && plan.ranges.back().node == node &&
        plan.ranges.back().first + plan.ranges.back().count == first) {
      plan.ranges.back().count += count;
    } else {
      plan.ranges.push_back({node, first, count});
    }
    plan.points += count;
  }

  const NodeHierarchy& hierarchy_;
  const std::function<bool(std::int32_t)>& loaded_;
  const std::function<std::array<std::uint32_t, 9>(std::int32_t)>& octant_offsets_;
  const std::function<std::uint8_t(std::int32_t)>& octants_in_view_;
  static constexpr std::uint8_t kEveryOctant = 0xFF;
  // By node index: compact arrays, not maps (a frame's frontier may hold
  // tens of thousands of nodes).
  static constexpr std::uint8_t kUnknown = 2;
  std::vector<Role> roles_;
  std::vector<std::uint8_t> covered_;
};

}  // namespace

DrawPlan PlanDraws(const NodeHierarchy& hierarchy, const LodFrontier& frontier,
                   const std::function<bool(std::int32_t)>& loaded,
                   const std::function<std::array<std::uint32_t, 9>(std::int32_t)>& octant_offsets,
                   const std::function<std::uint8_t(std::int32_t)>& octants_in_view) {
  DrawPlan plan;
  if (frontier.selected.empty()) return plan;
  Planner planner(hierarchy, loaded, octant_offsets, octants_in_view);
  for (std::int32_t n : frontier.selected) planner.SetRole(n, Role::kSelected);
  for (std::int32_t n : frontier.refined) planner.SetRole(n, Role::kRefined);
  planner.Draw(0, plan);
  return plan;
}

DrawPlan PlanClusterDraws(const NodeHierarchy& hierarchy, const LodFrontier& frontier,
                          const std::function<bool(std::int32_t)>& loaded,
                          const std::function<std::array<std::uint32_t, 9>(std::int32_t)>& octant_offsets,
                          const std::function<std::uint8_t(std::int32_t)>& octants_in_view) {
  DrawPlan plan;
  // By node: 1 reached, 2 reached and drawn. Parents come before their
  // children in `selected`.
  std::vector<std::uint8_t> state(hierarchy.nodes().size(), 0);
  const auto drawn = [&state](std::int32_t n) { return state[static_cast<std::size_t>(n)] == 2; };
  for (std::int32_t n : frontier.selected) {
    const std::int32_t parent = hierarchy.node(n).parent;
    state[static_cast<std::size_t>(n)] = loaded(n) && (parent < 0 || drawn(parent)) ? 2 : 1;
  }
  for (std::int32_t n : frontier.selected) {
    if (!drawn(n)) continue;
    const std::array<std::uint32_t, 9> offsets = octant_offsets(n);
    const std::uint8_t octants = octants_in_view ? octants_in_view(n) : 0xFF;
    for (int o = 0; o < 8; ++o) {
      if (!((octants >> o) & 1) || offsets[o + 1] <= offsets[o]) continue;
      const std::int32_t child = hierarchy.node(n).children[static_cast<std::size_t>(o)];
      const CutRole cut = child >= 0 && drawn(child) ? CutRole::kCut : CutRole::kCutFinal;
      const std::uint32_t first = offsets[o], count = offsets[o + 1] - offsets[o];
      DrawRange* last = plan.ranges.empty() ? nullptr : &plan.ranges.back();
      if (last != nullptr && last->node == n && last->cut == cut && last->first + last->count == first) {
        last->count += count;
      } else {
        plan.ranges.push_back({n, first, count, cut});
      }
      plan.points += count;
      plan.stand_ins += cut == CutRole::kCutFinal && child >= 0 && state[static_cast<std::size_t>(child)] == 1 ? 1 : 0;
    }
  }
  return plan;
}

}  // namespace octocosm
