#include "accuracy/pcl_random_sample.h"

#include <pcl/filters/random_sample.h>

#include <algorithm>
#include <string>

#include "accuracy/pcl_cloud.h"
#include "base/error.h"

namespace octocosm::accuracy {

Subsample PclRandomSample(const std::vector<double>& position, const std::vector<double>& mass, std::size_t count,
                          unsigned seed) {
  const std::size_t n = mass.size();
  if (position.size() != 3 * n || count > n) {
    throw Error::InvalidArgument("PclRandomSample: " + std::to_string(count) + " of " + std::to_string(n) +
                                 " points, with " + std::to_string(position.size()) + " coordinates");
  }
  pcl::RandomSample<pcl::PointXYZ> sampler;
  sampler.setInputCloud(ToFloatCloud(position));
  sampler.setSample(static_cast<unsigned>(count));
  sampler.setSeed(seed);
  pcl::Indices kept;
  sampler.filter(kept);
  if (kept.size() != count) {
    throw Error::InvalidArgument("pcl::RandomSample returned " + std::to_string(kept.size()) + " of " +
                                 std::to_string(count) + " points");
  }
  Subsample sample;
  sample.index.reserve(count);
  sample.weight.reserve(count);
  const double inflation = static_cast<double>(n) / static_cast<double>(count);
  for (const auto i : kept) {
    sample.index.push_back(static_cast<std::uint32_t>(i));
    sample.weight.push_back(mass[static_cast<std::size_t>(i)] * inflation);
  }
  return sample;
}

}  // namespace octocosm::accuracy
