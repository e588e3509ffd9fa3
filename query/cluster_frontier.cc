#include "query/cluster_frontier.h"

#include <algorithm>
#include <cmath>
#include <queue>
#include <utility>

#include "base/error.h"
#include "index/morton.h"

namespace octocosm {
namespace {

// The GPU evaluates each cluster's E in float; the frontier's bound is
// raised by this much so that rounding never leaves a child unloaded whose
// parent's cluster the GPU finds above tau (which would only coarsen the
// picture, never break the cut).
constexpr double kFloatSlack = 1e-4;

// The largest E = s / sqrt(1 + s / r), s = a / (q D^2), inside a sphere of
// `radius` whose centre lies `distance` from the camera: D the gap between
// them (E infinite at 0); 0 for an empty sphere (radius < 0).
double LargestErrorInSphere(double distance, double radius, double mass_variance, double mass, double q) {
  if (radius < 0 || !(mass_variance > 0) || !(mass > 0)) return 0;
  const double gap = std::max(0.0, distance - radius);
  if (!(gap > 0)) return INFINITY;
  const double spread = mass_variance / (q * gap * gap);
  return std::isfinite(spread) ? spread / std::sqrt(1 + spread / mass) : INFINITY;
}

bool Exceeds(const OctantRefineBound& bound, const std::array<double, 3>& camera, double q, double threshold) {
  return LargestClusterError(bound, camera, q) * (1 + kFloatSlack) > threshold;
}

// `camera` relative to the node's corner.
bool Exceeds(const NodeRefineBounds::Sphere& bound, const std::array<double, 3>& camera, double q, double threshold) {
  double d2 = 0;
  for (std::size_t a = 0; a < 3; ++a) {
    const double d = double{bound.centre[a]} - camera[a];
    d2 += d * d;
  }
  return LargestErrorInSphere(std::sqrt(d2), bound.radius, bound.mass_variance, bound.mass, q) * (1 + kFloatSlack) >
         threshold;
}

// The float nearest above v (v finite and >= 0).
float RoundedUp(double v) {
  const float f = static_cast<float>(v);
  return double{f} >= v ? f : std::nextafter(f, INFINITY);
}

// `bound` in floats relative to `corner`, holding what it held.
NodeRefineBounds::Sphere SphereOf(const OctantRefineBound& bound, const std::array<double, 3>& corner) {
  NodeRefineBounds::Sphere s;
  double moved2 = 0;
  for (std::size_t a = 0; a < 3; ++a) {
    const double relative = bound.centre[a] - corner[a];
    s.centre[a] = static_cast<float>(relative);
    const double moved = double{s.centre[a]} - relative;
    moved2 += moved * moved;
  }
  s.radius = RoundedUp(bound.radius + std::sqrt(moved2));
  s.mass_variance = RoundedUp(bound.mass_variance);
  s.mass = RoundedUp(bound.mass);
  return s;
}

// The centre of the cube of edge `size` at corner + size * (cell + 1/2) per axis.
std::array<double, 3> CellCentre(const std::array<double, 3>& corner, double size, std::size_t cell_x,
                                 std::size_t cell_y, std::size_t cell_z) {
  return {corner[0] + size * (static_cast<double>(cell_x) + 0.5), corner[1] + size * (static_cast<double>(cell_y) + 0.5),
          corner[2] + size * (static_cast<double>(cell_z) + 0.5)};
}

// Grows `bound` (a sphere about its centre) to hold `member`'s sphere and bounds.
void Hold(OctantRefineBound& bound, const OctantRefineBound& member) {
  double d2 = 0;
  for (std::size_t a = 0; a < 3; ++a) {
    const double d = member.centre[a] - bound.centre[a];
    d2 += d * d;
  }
  bound.radius = std::max(bound.radius, std::sqrt(d2) + member.radius);
  bound.mass_variance = std::max(bound.mass_variance, member.mass_variance);
  bound.mass = std::max(bound.mass, member.mass);
}

// Whether entry `index` of `level` bounds a cluster that may have an error above the threshold.
bool AnyClusterAbove(const NodeRefineBounds::Tree& tree, std::size_t level, std::size_t index,
                     const std::array<double, 3>& camera, double q, double threshold) {
  if (!Exceeds(tree[level][index], camera, q, threshold)) return false;
  if (level == 0) return true;
  const std::size_t end = std::min(tree[level - 1].size(), (index + 1) * NodeRefineBounds::kFanOut);
  for (std::size_t i = index * NodeRefineBounds::kFanOut; i < end; ++i) {
    if (AnyClusterAbove(tree, level - 1, i, camera, q, threshold)) return true;
  }
  return false;
}

// Whether a cluster of the octant may have an error above the threshold.
bool AnyClusterAbove(const NodeRefineBounds& node, std::size_t octant, const std::array<double, 3>& camera, double q,
                     double threshold) {
  const NodeRefineBounds::Tree& tree = node.trees[octant];
  if (tree.empty()) return true;
  const std::array<double, 3> relative = {camera[0] - node.corner[0], camera[1] - node.corner[1], camera[2] - node.corner[2]};
  for (std::size_t i = 0; i < tree.back().size(); ++i) {
    if (AnyClusterAbove(tree, tree.size() - 1, i, relative, q, threshold)) return true;
  }
  return false;
}

// The bound of `members`: a sphere about the middle of their centres' box.
OctantRefineBound BoundOf(std::span<const OctantRefineBound> members) {
  OctantRefineBound b;
  for (std::size_t a = 0; a < 3; ++a) {
    double low = INFINITY, high = -INFINITY;
    for (const OctantRefineBound& m : members) {
      low = std::min(low, m.centre[a]);
      high = std::max(high, m.centre[a]);
    }
    b.centre[a] = 0.5 * (low + high);
  }
  for (const OctantRefineBound& m : members) Hold(b, m);
  return b;
}

// The tree of an octant's clusters, ordered along a Morton curve in `node`.
NodeRefineBounds::Tree TreeOf(const NodeCube& node, std::span<const OctantRefineBound> clusters) {
  NodeRefineBounds::Tree tree;
  if (clusters.empty()) return tree;
  std::vector<std::vector<OctantRefineBound>> levels;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> order(clusters.size());
  constexpr double kCells = 1 << 20;
  for (std::size_t i = 0; i < clusters.size(); ++i) {
    std::uint64_t code = 0;
    for (std::size_t a = 0; a < 3; ++a) {
      const double t = std::clamp((clusters[i].centre[a] - node.origin[a]) / node.size * kCells, 0.0, kCells - 1);
      code |= SpreadBits3(static_cast<std::uint64_t>(t)) << a;
    }
    order[i] = {code, static_cast<std::uint32_t>(i)};
  }
  std::sort(order.begin(), order.end());
  levels.emplace_back();
  levels.back().reserve(clusters.size());
  for (const auto& [code, i] : order) levels.back().push_back(clusters[i]);
  while (levels.back().size() > NodeRefineBounds::kFanOut) {
    const std::span<const OctantRefineBound> below = levels.back();
    std::vector<OctantRefineBound> level;
    level.reserve((below.size() + NodeRefineBounds::kFanOut - 1) / NodeRefineBounds::kFanOut);
    for (std::size_t i = 0; i < below.size(); i += NodeRefineBounds::kFanOut) {
      level.push_back(BoundOf(below.subspan(i, std::min(NodeRefineBounds::kFanOut, below.size() - i))));
    }
    levels.push_back(std::move(level));
  }
  // In double each level's spheres hold the level below's, down to the
  // clusters'; in floats each sphere grows by its own rounding, so that it
  // still holds every cluster below it.
  for (const std::vector<OctantRefineBound>& level : levels) {
    tree.emplace_back();
    tree.back().reserve(level.size());
    for (const OctantRefineBound& b : level) tree.back().push_back(SphereOf(b, node.origin));
  }
  return tree;
}

}  // namespace

NodeRefineBounds NodeRefineBounds::Of(const NodeCube& node, std::span<const OctantRefineBound> clusters,
                                      const std::array<std::uint32_t, 9>& octant_first) {
  NodeRefineBounds b;
  b.corner = node.origin;
  for (std::size_t o = 0; o < 8; ++o) {
    OctantRefineBound& octant = b.octants[o];
    octant.centre = CellCentre(node.origin, node.size / 2, o & 1, (o >> 1) & 1, (o >> 2) & 1);
    const std::size_t end = std::min<std::size_t>(octant_first[o + 1], clusters.size());
    const std::size_t first = std::min<std::size_t>(octant_first[o], end);
    const std::span<const OctantRefineBound> members = clusters.subspan(first, end - first);
    for (const OctantRefineBound& cluster : members) Hold(octant, cluster);
    b.trees[o] = TreeOf(node, members);
  }
  return b;
}

double LargestClusterError(const OctantRefineBound& bound, const std::array<double, 3>& camera, double q) {
  const double dx = bound.centre[0] - camera[0], dy = bound.centre[1] - camera[1], dz = bound.centre[2] - camera[2];
  return LargestErrorInSphere(std::sqrt(dx * dx + dy * dy + dz * dz), bound.radius, bound.mass_variance, bound.mass, q);
}

LodFrontier SelectClusterFrontier(const NodeHierarchy& hierarchy, const Cube& cube, const Camera& camera,
                                  const ClusterLodOptions& options,
                                  const std::function<const NodeRefineBounds*(std::int32_t)>& bounds) {
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
    const NodeRefineBounds* loaded = bounds(index);
    if (loaded == nullptr) continue;
    bool refined = false;
    const NodeHierarchy::Node& node = hierarchy.node(index);
    for (int o = 0; o < 8; ++o) {
      const std::int32_t c = node.children[static_cast<std::size_t>(o)];
      if (c < 0) continue;
      const double error = LargestClusterError(loaded->octants[static_cast<std::size_t>(o)], camera.position, q);
      if (!Exceeds(loaded->octants[static_cast<std::size_t>(o)], camera.position, q, options.threshold)) continue;
      if (!AnyClusterAbove(*loaded, static_cast<std::size_t>(o), camera.position, q, options.threshold)) continue;
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
