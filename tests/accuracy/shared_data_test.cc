// The PCL cross-check on the real snapshots in ../shared/data (labels
// accuracy and shared-data; skipped when the folder is absent), through the
// whole pipeline: each snapshot is ingested (octocosm ingest's code path) and
// its store read back block by block.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <ostream>
#include <string>

#include "accuracy/level_comparison.h"
#include "accuracy/level_samples.h"
#include "accuracy/pcl_octree_leaves.h"
#include "accuracy/snapshot_points.h"
#include "index/dataset.h"
#include "ingest/ingest.h"
#include "tests/ingest/ingest_fixture.h"

namespace octocosm::accuracy {
namespace {

namespace fs = std::filesystem;
using testing_support::IngestFixture;

struct Snapshot {
  const char* name;
  const char* path;  // under ../shared/data
  Cube dyadic;       // a dyadic cube holding every particle, for the voxel census
  // The least fraction of pcl::RandomSample's sparse-voxel coverage the levels
  // must reach: more than all of it (1) on clustered data; parity within 5%
  // on the z = 10 initial conditions, uniform to a few percent, where there
  // are no sparse regions for density weighting to favour.
  double coverage_floor;
};

// What ctest and gtest print for a case (instead of its bytes).
void PrintTo(const Snapshot& snapshot, std::ostream* out) { *out << snapshot.path; }

const Snapshot kSnapshots[] = {
    {"GalaxyIc", "gadget2_ics/galaxy_littleendian.dat", Cube{{-256, -256, -256}, 512, false}, 1.0},
    {"LcdmGasZ10", "gadget2_ics/lcdm_gas_littleendian.dat", Cube{{0, 0, 0}, 65536, false}, 0.95},
    {"Format2TwoFilesZ2", "gadget2_format2_multifile/test_g2_snap", Cube{{0, 0, 0}, 4096, false}, 1.0},
    {"Hdf5CollisionLast", "gadget4_hdf5_galaxy_collision_timeseries/snapshot_020.hdf5",
     Cube{{-2048, -2048, -2048}, 4096, false}, 1.0},
};

class SharedDataCrossCheck : public IngestFixture, public ::testing::WithParamInterface<Snapshot> {
 protected:
  static constexpr const char* kData = OCTOCOSM_SHARED_DATA;
  static constexpr std::size_t kCapacity = 1000;  // several levels from these 8000-65000 particles

  void SetUp() override {
    if (!fs::is_directory(kData)) GTEST_SKIP() << "no shared data folder at " << kData;
    input_ = std::string(kData) + "/" + GetParam().path;
    points_ = ReadSnapshotPoints(input_);
  }

  // The snapshot ingested into `name` (its own cube unless `cube` is given),
  // read back as levels.
  LevelSamples IngestLevels(const std::string& name, const std::optional<Cube>& cube, Cube& used) {
    IngestOptions o = Options({input_}, name);
    o.tree.capacity = kCapacity;
    o.tree.coarse = CoarsePoints::kSample;  // PCL's random sample checks the subselection
    o.cube = cube;
    Ingest(o);
    const Dataset dataset = Dataset::Open(o.output);
    used = dataset.cube(0);
    LevelSamples levels(points_.id);
    levels.AddStore(dataset, 0);
    return levels;
  }

  std::string input_;
  ParticleChunk points_;
};

// Bound: zero mismatches between every particle's leaf in the store ingest
// writes (on the cube ingest chooses: the periodic box, or the bounding cube)
// and its leaf in PCL's adaptive octree with the same capacity and depth.
TEST_P(SharedDataCrossCheck, EveryLeafKeyEqualsPclAdaptiveOctreeLeaf) {
  Cube cube;
  const std::vector<NodeKey> octocosm = IngestLevels("store", std::nullopt, cube).Leaves();
  const std::vector<NodeKey> pcl = PclOctreeLeaves(points_.position, cube, kCapacity, kMaxLevel);
  std::size_t mismatches = 0;
  for (std::size_t i = 0; i < octocosm.size(); ++i) {
    if (octocosm[i] != pcl[i] && mismatches++ < 5) {
      ADD_FAILURE() << "particle ID " << points_.id[i] << ": octocosm " << octocosm[i].Path() << ", PCL "
                    << pcl[i].Path();
    }
  }
  EXPECT_EQ(mismatches, 0u);
}

// On the real particle distributions (two or three mass species in each) and
// a dyadic cube: at every sampled level the store's level keeps more of the
// sparse voxels than pcl::RandomSample with as many points (at least the
// snapshot's coverage floor times as many), and its voxel mass estimates are
// unbiased: |mean relative error| <= 4 standard errors + 0.01 for all, sparse
// and dense voxels (the bounds of LevelScores.VoxelMassEstimatesAreUnbiased).
TEST_P(SharedDataCrossCheck, LevelsKeepMoreSparseVoxelsThanPclRandomSampleWithoutBias) {
  Cube cube;
  const std::vector<LevelSamples> trees = {IngestLevels("dyadic", GetParam().dyadic, cube)};
  const std::vector<LevelComparison> levels = CompareLevels(points_, trees, cube, kCapacity, 7);
  ASSERT_GE(levels.size(), 1u);
  for (const LevelComparison& l : levels) {
    SCOPED_TRACE("level " + std::to_string(l.level));
    EXPECT_EQ(l.disagreements, 0u);
    const SampleScore& octocosm = l.octocosm[0];
    if (GetParam().coverage_floor >= 1) {
      EXPECT_GT(octocosm.sparse_voxels_kept, l.random.sparse_voxels_kept);
    } else {
      EXPECT_GE(octocosm.sparse_voxels_kept, GetParam().coverage_floor * l.random.sparse_voxels_kept);
    }
    for (const auto* d : {&octocosm.all, &octocosm.sparse, &octocosm.dense}) {
      if (d->voxels < 20) continue;
      EXPECT_LE(std::fabs(d->mean), 4 * d->standard_error + 0.01)
          << "mean relative error " << d->mean << " +- " << d->standard_error << " over " << d->voxels << " voxels";
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Snapshots, SharedDataCrossCheck, ::testing::ValuesIn(kSnapshots),
                         [](const ::testing::TestParamInfo<Snapshot>& param) { return param.param.name; });

}  // namespace
}  // namespace octocosm::accuracy
