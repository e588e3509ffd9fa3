#include "query/cluster_frontier.h"

#include <cmath>
#include <queue>
#include <utility>

#include "base/error.h"

namespace octocosm {
namespace {

// The GPU evaluates each cluster's E in float; the frontier's bound is
// raised by this much so that rounding never leaves a child unloaded whose
// parent's cluster the GPU finds above tau (which would only coarsen the
// picture, never break the cut).
constexpr double kFloatSlack = 1e-4;

}  // namespace

double LargestClusterError(const OctantRefineBound& bound, const std::array<double, 3>& camera, double q) {
  if (bound.radius < 0 || !(bound.mass_variance > 0) || !(bound.mass > 0)) return 0;
  const double dx = bound.centre[0] - camera[0], dy = bound.centre[1] - camera[1], dz = bound.centre[2] - camera[2];
  const double gap = std::max(0.0, std::sqrt(dx * dx + dy * dy + dz * dz) - bound.radius);
  if (!(gap > 0)) return INFINITY;
  const double spread = bound.mass_variance / (q * gap * gap);
  return std::isfinite(spread) ? spread / std::sqrt(1 + spread / bound.mass) : INFINITY;
}

LodFrontier SelectClusterFrontier(const NodeHierarchy& hierarchy, const Cube& cube, const Camera& camera,
                                  const ClusterLodOptions& options,
                                  const std::function<const OctantRefineBounds*(std::int32_t)>& bounds) {
  if (!(options.threshold >= 0) || !std::isfinite(options.threshold)) {
    throw Error::InvalidArgument("the cluster error threshold must be finite and >= 0");
  }
  if (!(options.focal_pixels > 0) || !std::isfinite(options.focal_pixels)) {
    throw Error::InvalidArgument("the focal length must be > 0 pixels");
  }
  if (!(options.cull_margin >= 0) || !std::isfinite(options.cull_margin)) {
    throw Error::InvalidArgument("the culling margin must be >= 0");
  }
  LodFrontier f;
  f.culler = ViewCuller(camera, cube, options.cull_margin);
  if (hierarchy.empty()) return f;
  ++f.nodes_visited;
  if (!f.culler.MayMeet(cube.NodeCubeOf(hierarchy.node(0).key))) {
    ++f.nodes_culled;
    return f;
  }
  const double half_pixel = 0.5 / options.focal_pixels;
  const double q = half_pixel * half_pixel;

  using Candidate = std::pair<double, std::int32_t>;  // (largest error of the clusters it refines, node)
  std::priority_queue<Candidate> queue;
  queue.emplace(INFINITY, 0);
  f.points = hierarchy.node(0).entry.point_count;
  while (!queue.empty()) {
    const std::int32_t index = queue.top().second;
    queue.pop();
    f.selected.push_back(index);
    f.load_order.push_back(index);
    const OctantRefineBounds* octants = bounds(index);
    if (octants == nullptr) continue;
    bool refined = false;
    const NodeHierarchy::Node& node = hierarchy.node(index);
    for (int o = 0; o < 8; ++o) {
      const std::int32_t c = node.children[static_cast<std::size_t>(o)];
      if (c < 0) continue;
      const double error = LargestClusterError((*octants)[static_cast<std::size_t>(o)], camera.position, q);
      if (!(error * (1 + kFloatSlack) > options.threshold)) continue;
      ++f.nodes_visited;
      const NodeHierarchy::Node& child = hierarchy.node(c);
      if (!f.culler.MayMeet(cube.NodeCubeOf(child.key))) {
        ++f.nodes_culled;
        continue;
      }
      if (options.point_budget > 0 && f.points + child.entry.point_count > options.point_budget) {
        f.budget_reached = true;
        continue;
      }
      f.points += child.entry.point_count;
      queue.emplace(error, c);
      refined = true;
    }
    if (refined) f.refined.push_back(index);
  }
  return f;
}

}  // namespace octocosm
