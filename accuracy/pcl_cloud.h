// Octocosm positions (doubles, x,y,z interleaved) as a PCL point cloud
// (pcl::PointXYZ holds floats). Internal to accuracy/: nothing else includes
// PCL headers.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <cstdint>
#include <span>
#include <vector>

namespace octocosm::accuracy {

// The points `subset` (indices into position / 3), or every point when
// `subset` is empty. PCL works in float32: a coordinate float32 cannot hold
// exactly would be compared after rounding, so it is refused with
// Error::InvalidArgument naming the point.
pcl::PointCloud<pcl::PointXYZ>::Ptr ToFloatCloud(const std::vector<double>& position,
                                                 std::span<const std::uint32_t> subset = {});

}  // namespace octocosm::accuracy
