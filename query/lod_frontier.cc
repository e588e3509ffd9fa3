#include "query/lod_frontier.h"

#include <cmath>
#include <queue>
#include <utility>

#include "base/error.h"

namespace octocosm {

LodFrontier SelectLodFrontier(const NodeHierarchy& hierarchy, const Cube& cube, const ScreenErrorView& view,
                              const LodOptions& options) {
  if (!(options.pixel_threshold > 0) || !std::isfinite(options.pixel_threshold)) {
    throw Error::InvalidArgument("the level-of-detail threshold must be > 0 pixels");
  }
  if (!(options.cull_margin >= 0) || !std::isfinite(options.cull_margin)) {
    throw Error::InvalidArgument("the culling margin must be >= 0");
  }
  LodFrontier f;
  f.culler = ViewCuller(view.camera, cube, options.cull_margin);
  if (hierarchy.empty()) return f;
  const auto visible = [&f](const NodeCube& c) { return f.culler.MayMeet(c); };
  const ScreenErrorMeter error(view);

  using Candidate = std::pair<double, std::int32_t>;  // (error, node): largest error first
  std::priority_queue<Candidate> queue;
  ++f.nodes_visited;
  const NodeCube root = cube.NodeCubeOf(hierarchy.node(0).key);
  if (!visible(root)) {
    ++f.nodes_culled;
    return f;
  }
  queue.emplace(error(root, hierarchy.node(0).entry.point_count), 0);
  f.points = hierarchy.node(0).entry.point_count;
  std::vector<Candidate> children;  // in view, with their errors
  while (!queue.empty()) {
    const auto [node_error, index] = queue.top();
    queue.pop();
    // The next node is usually the new top: ask for it now, while this one's
    // children are tested. Taken in order of error, nodes come from all over
    // the hierarchy, and at tens of thousands of nodes waiting for each
    // from memory was most of the selection's time.
    if (!queue.empty()) __builtin_prefetch(&hierarchy.node(queue.top().second));
    const NodeHierarchy::Node& node = hierarchy.node(index);
    f.load_order.push_back(index);
    if (!(node_error > options.pixel_threshold) || node.is_leaf()) {
      f.selected.push_back(index);
      continue;
    }
    children.clear();
    std::uint64_t child_points = 0;
    for (std::int32_t c : node.children) {
      if (c < 0) continue;
      ++f.nodes_visited;
      const NodeHierarchy::Node& child = hierarchy.node(c);
      const NodeCube child_cube = cube.NodeCubeOf(child.key);
      if (!visible(child_cube)) {
        ++f.nodes_culled;
        continue;
      }
      children.push_back({error(child_cube, child.entry.point_count), c});
      child_points += child.entry.point_count;
    }
    const std::uint64_t refined_points = f.points - node.entry.point_count + child_points;
    if (options.point_budget > 0 && refined_points > options.point_budget) {
      // Drawn as it is; a node further down the queue whose children cost
      // less may still fit.
      f.budget_reached = true;
      f.selected.push_back(index);
      continue;
    }
    f.points = refined_points;
    f.refined.push_back(index);
    for (const Candidate& c : children) queue.push(c);
  }
  return f;
}

}  // namespace octocosm
