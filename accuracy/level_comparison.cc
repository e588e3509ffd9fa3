#include "accuracy/level_comparison.h"

#include "accuracy/pcl_random_sample.h"
#include "accuracy/voxel_census.h"
#include "base/error.h"

namespace octocosm::accuracy {

std::vector<LevelComparison> CompareLevels(const ParticleChunk& points, std::span<const LevelSamples> trees,
                                           const Cube& cube, std::size_t capacity, unsigned seed) {
  if (trees.empty()) throw Error::InvalidArgument("CompareLevels: no trees to compare");
  std::vector<LevelComparison> levels;
  const int per_node = VoxelBitsPerNode(capacity);
  for (int level = 0; level < trees[0].depth() && level + per_node <= kMaxLevel; ++level) {
    const Subsample first = trees[0].AtLevel(level);
    if (first.size() >= points.size()) break;  // the whole data: nothing was sampled
    const VoxelCensus census = CountVoxels(points.position, points.mass, cube, level + per_node);
    LevelComparison compared;
    compared.level = level;
    compared.voxel_bits = level + per_node;
    compared.voxels = census.voxels();
    compared.disagreements = census.disagreements;
    for (const LevelSamples& tree : trees) {
      compared.octocosm.push_back(ScoreSample(census, &tree == trees.data() ? first : tree.AtLevel(level)));
    }
    compared.random = ScoreSample(
        census, PclRandomSample(points.position, points.mass, first.size(), seed + static_cast<unsigned>(level)));
    levels.push_back(std::move(compared));
  }
  return levels;
}

}  // namespace octocosm::accuracy
