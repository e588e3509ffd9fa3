// How faithfully a weighted subsample of a point set represents it, voxel by
// voxel (the voxels of a VoxelCensus): what fraction of the occupied voxels it
// keeps, how much mass lies in the voxels it drops, and the distribution of
// the relative error of its mass estimate per voxel,
//
//   r_v = (sum of the sample's weights in voxel v) / (true mass of v) - 1,
//
// over all occupied voxels, and split into sparse and dense ones. A voxel is
// sparse when it holds fewer than n / m points (n points in all, m in the
// sample): a uniform sample of m points expects to keep less than one of them.
// An unbiased sample has E[r_v] = 0 in every voxel, so the mean of r_v over
// the voxels is zero up to its standard error (reported with it).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "accuracy/voxel_census.h"

namespace octocosm::accuracy {

// The voxels a level of detail is scored on: a level-L sample is compared on
// the cells of level L + VoxelBitsPerNode(capacity), the finest grid on which
// a full node (capacity points) could still give every point a voxel of its
// own: 2^b cells per node axis with 8^b >= capacity (5 for 16000).
int VoxelBitsPerNode(std::size_t capacity);

// A subset of a point set's points (indices into it), each with the mass it
// stands for.
struct Subsample {
  std::vector<std::uint32_t> index;
  std::vector<double> weight;
  std::size_t size() const { return index.size(); }
};

struct ErrorDistribution {
  std::size_t voxels = 0;
  double mean = 0;
  double standard_error = 0;  // of the mean: sd / sqrt(voxels)
  double p05 = 0, p25 = 0, median = 0, p75 = 0, p95 = 0;
};

struct SampleScore {
  std::size_t points = 0;         // in the sample
  std::size_t voxels = 0;         // occupied by the full set
  std::size_t sparse_voxels = 0;
  double sparse_below = 0;        // the sparse threshold n / m, in points
  double voxels_kept = 0;         // fraction of occupied voxels holding a sample point
  double sparse_voxels_kept = 0;  // the same among sparse voxels (0 when there are none)
  double mass_dropped = 0;        // fraction of the mass in voxels holding no sample point
  ErrorDistribution all, sparse, dense;
};

// Scores `sample` (indices into the census's points) against the census.
// Throws Error::InvalidArgument for an empty sample, an index out of range or
// mismatched lengths.
SampleScore ScoreSample(const VoxelCensus& census, const Subsample& sample);

}  // namespace octocosm::accuracy
