// The baseline a level-of-detail sample is compared with: a uniform random
// sample of the same number of points, drawn by pcl::RandomSample.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "accuracy/sample_score.h"

namespace octocosm::accuracy {

// `count` of the points of `position` (x,y,z interleaved, float32 values),
// drawn uniformly without replacement by pcl::RandomSample with `seed` (which
// draws with std::rand: deterministic for a seed, not thread-safe). Each kept
// point i stands for mass[i] * n / count, the Horvitz-Thompson weight of a
// point kept with probability count / n, so every region's estimate is
// unbiased. count <= n.
Subsample PclRandomSample(const std::vector<double>& position, const std::vector<double>& mass, std::size_t count,
                          unsigned seed);

}  // namespace octocosm::accuracy
