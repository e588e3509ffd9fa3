// Octocosm's levels of detail against a uniform random sample of the same
// size (pcl::RandomSample), level by level, on the voxels of each level
// (VoxelBitsPerNode): the cross-check of coverage and density,
// shared by tests/accuracy and octocosm-bench-accuracy.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "accuracy/level_samples.h"
#include "accuracy/sample_score.h"
#include "index/cube.h"
#include "index/particle_chunk.h"

namespace octocosm::accuracy {

struct LevelComparison {
  int level = 0;
  int voxel_bits = 0;                 // the voxels are the cells of this level
  std::size_t voxels = 0;             // occupied by the data
  std::size_t disagreements = 0;      // PCL voxels that are not octocosm cells (VoxelCensus)
  std::vector<SampleScore> octocosm;  // one per tree compared
  SampleScore random;                 // pcl::RandomSample with as many points as the first tree's level
};

// For each level of the trees (built from `points` in `cube` with node
// capacity `capacity`, e.g. at several values of alpha) at which the first
// tree's sample holds fewer points than the data: the census of the data on
// that level's voxels (pcl::VoxelGrid), each tree's level scored against it,
// and pcl::RandomSample (seed `seed` + level) scored the same way. The cube
// must be dyadic (accuracy/voxel_census.h).
std::vector<LevelComparison> CompareLevels(const ParticleChunk& points, std::span<const LevelSamples> trees,
                                           const Cube& cube, std::size_t capacity, unsigned seed);

}  // namespace octocosm::accuracy
