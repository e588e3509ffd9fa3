#include "accuracy/pcl_cloud.h"

#include <string>

#include "base/error.h"

namespace octocosm::accuracy {
namespace {

float ExactFloat(const std::vector<double>& position, std::size_t point, int axis) {
  const double x = position[3 * point + static_cast<std::size_t>(axis)];
  const auto f = static_cast<float>(x);
  if (static_cast<double>(f) != x) {
    throw Error::InvalidArgument("point " + std::to_string(point) + " axis " + std::to_string(axis) + ": " +
                                 std::to_string(x) + " is not a float32 value; PCL would compare it rounded");
  }
  return f;
}

}  // namespace

pcl::PointCloud<pcl::PointXYZ>::Ptr ToFloatCloud(const std::vector<double>& position,
                                                 std::span<const std::uint32_t> subset) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  const std::size_t n = subset.empty() ? position.size() / 3 : subset.size();
  cloud->reserve(n);
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t i = subset.empty() ? k : subset[k];
    cloud->push_back(pcl::PointXYZ(ExactFloat(position, i, 0), ExactFloat(position, i, 1), ExactFloat(position, i, 2)));
  }
  return cloud;
}

}  // namespace octocosm::accuracy
