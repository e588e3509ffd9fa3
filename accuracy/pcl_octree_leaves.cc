#include "accuracy/pcl_octree_leaves.h"

#include <pcl/octree/octree_pointcloud_pointvector.h>

#include <cmath>
#include <string>

#include "accuracy/pcl_cloud.h"
#include "base/error.h"

namespace octocosm::accuracy {
namespace {

using Octree = pcl::octree::OctreePointCloudPointVector<pcl::PointXYZ>;

// Throws unless PCL's box and depth are the ones it was given.
void CheckGeometry(const Octree& octree, const Cube& cube, int max_level, const char* when) {
  double lo[3], hi[3];
  octree.getBoundingBox(lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
  for (int a = 0; a < 3; ++a) {
    if (lo[a] != cube.origin[a] || hi[a] != cube.origin[a] + cube.size) {
      throw Error::InvalidArgument(std::string("PCL moved its bounding box ") + when + " (axis " + std::to_string(a) +
                                   ": [" + std::to_string(lo[a]) + ", " + std::to_string(hi[a]) +
                                   "]): its keys would not be octocosm's");
    }
  }
  if (static_cast<int>(octree.getTreeDepth()) != max_level) {
    throw Error::InvalidArgument(std::string("PCL chose depth ") + std::to_string(octree.getTreeDepth()) + " " +
                                 when + ", not " + std::to_string(max_level));
  }
}

}  // namespace

std::vector<NodeKey> PclOctreeLeaves(const std::vector<double>& position, const Cube& cube, std::size_t capacity,
                                     int max_level) {
  cube.Validate();
  const std::size_t n = position.size() / 3;
  if (max_level < 1 || max_level > kMaxLevel || capacity == 0 || n <= capacity) {
    throw Error::InvalidArgument("PclOctreeLeaves: needs 1 <= max_level <= 21 (got " + std::to_string(max_level) +
                                 ") and more than capacity " + std::to_string(capacity) + " points (got " +
                                 std::to_string(n) + ")");
  }
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      const double x = position[3 * i + static_cast<std::size_t>(a)];
      if (!(x >= cube.origin[a] && x < cube.origin[a] + cube.size)) {
        throw Error::InvalidArgument("PclOctreeLeaves: point " + std::to_string(i) + " axis " + std::to_string(a) +
                                     " (" + std::to_string(x) + ") is not inside [origin, origin + size)");
      }
    }
  }
  const auto cloud = ToFloatCloud(position);

  Octree octree(std::ldexp(cube.size, -max_level));
  octree.setInputCloud(cloud);
  octree.defineBoundingBox(cube.origin[0], cube.origin[1], cube.origin[2], cube.origin[0] + cube.size,
                           cube.origin[1] + cube.size, cube.origin[2] + cube.size);
  CheckGeometry(octree, cube, max_level, "when given the cube");
  octree.enableDynamicDepth(capacity);
  octree.addPointsFromInputCloud();
  CheckGeometry(octree, cube, max_level, "while adding the points");

  std::vector<NodeKey> leaf(n);
  std::size_t assigned = 0;
  for (auto it = octree.leaf_depth_begin(); it != octree.leaf_depth_end(); ++it) {
    const pcl::octree::OctreeKey& key = it.getCurrentOctreeKey();
    const NodeKey node = NodeKey::FromCell(static_cast<int>(it.getCurrentOctreeDepth()), {key.x, key.y, key.z});
    for (const auto index : it.getLeafContainer().getPointIndicesVector()) {
      leaf.at(static_cast<std::size_t>(index)) = node;
      ++assigned;
    }
  }
  if (assigned != n) {
    throw Error::InvalidArgument("PCL's leaves hold " + std::to_string(assigned) + " points of " + std::to_string(n));
  }
  return leaf;
}

}  // namespace octocosm::accuracy
