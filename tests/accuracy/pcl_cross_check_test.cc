// octocosm against the Point Cloud Library (docs/ACCURACY.md), on
// generated clustered points:
//  - keys: every point's leaf in octocosm's tree is its leaf in PCL's
//    adaptive octree, exactly, cell faces included;
//  - voxels: pcl::VoxelGrid's voxels are octocosm's cells, exactly;
//  - coverage and density: each level of detail, scored voxel by voxel
//    against the full data, next to pcl::RandomSample with as many points.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <algorithm>
#include <set>

#include "accuracy/level_comparison.h"
#include "accuracy/level_samples.h"
#include "accuracy/pcl_octree_leaves.h"
#include "accuracy/voxel_census.h"
#include "base/error.h"
#include "tests/accuracy/clustered_points.h"

namespace octocosm::accuracy {
namespace {

using testing_support::AddPoint;
using testing_support::ClusteredFloatPoints;

// The bounding cube ingest would choose for `points` (Cube::FromBounds), with
// its edge rounded up to a float32 value so that float32 coordinates can lie
// exactly on its cell faces. Not a power of two.
Cube FloatBoundingCube(const ParticleChunk& points) {
  std::array<double, 3> lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  for (std::size_t i = 0; i < points.position.size(); ++i) {
    lo[i % 3] = std::min(lo[i % 3], points.position[i]);
    hi[i % 3] = std::max(hi[i % 3], points.position[i]);
  }
  Cube cube = Cube::FromBounds(lo, hi);
  auto size = static_cast<float>(cube.size);
  if (size < cube.size) size = std::nextafter(size, INFINITY);
  cube.size = size;
  return cube;
}

// Appends a point on every inner cell face of levels 1..max_face_level, on
// each axis, that is exactly a float32 coordinate: the data point nearest to
// the face on that axis, moved onto it (so it stays where the data are dense
// and the tree deep). Returns the face level of each point added.
std::vector<int> AddFacePoints(ParticleChunk& points, const Cube& cube, int max_face_level) {
  std::vector<int> face_level;
  const std::size_t data = points.size();
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<std::pair<double, std::size_t>> along;  // coordinate on `axis`, point
    for (std::size_t i = 0; i < data; ++i) along.emplace_back(points.position[3 * i + axis], i);
    std::sort(along.begin(), along.end());
    for (int level = 1; level <= max_face_level; ++level) {
      for (std::uint64_t k = 1; k < (std::uint64_t{1} << level); ++k) {
        const double product = static_cast<double>(k) * cube.size;
        const double offset = std::ldexp(product, -level);
        const double x = cube.origin[axis] + offset;
        if (std::fma(static_cast<double>(k), cube.size, -product) != 0 || x - cube.origin[axis] != offset ||
            static_cast<double>(static_cast<float>(x)) != x) {
          continue;
        }
        auto nearest = std::lower_bound(along.begin(), along.end(), std::make_pair(x, std::size_t{0}));
        if (nearest == along.end()) --nearest;
        double p[3];
        std::copy_n(&points.position[3 * nearest->second], 3, p);
        p[axis] = x;
        AddPoint(points, p[0], p[1], p[2]);
        face_level.push_back(level);
      }
    }
  }
  return face_level;
}

struct KeyComparison {
  std::size_t points = 0, mismatches = 0, faces = 0, faces_deciding = 0;
};

// Builds both trees of 20000 clustered points in `cube`, plus every exact
// face point of levels 1-12 and 300 coincident points, with capacity 50 and
// depth limit 21, and compares every point's leaf.
KeyComparison CompareLeafKeys(const Cube& cube, std::uint64_t seed) {
  const std::size_t data = 20000;
  ParticleChunk points = ClusteredFloatPoints(data, seed, cube);
  const std::vector<int> face_level = AddFacePoints(points, cube, 12);
  for (int i = 0; i < 300; ++i) AddPoint(points, points.position[0], points.position[1], points.position[2]);

  SubtreeOptions options;
  options.capacity = 50;
  // The density grid shapes samples, not the tree; a coarse one keeps the
  // many small leaves cheap (each estimate walks every fine cell).
  options.sampler.density_grid_bits = 2;
  const std::vector<NodeKey> octocosm = BuildLevelSamples(points, cube, options).Leaves();
  const std::vector<NodeKey> pcl = PclOctreeLeaves(points.position, cube, options.capacity, kMaxLevel);
  KeyComparison result;
  result.points = points.size();
  result.faces = face_level.size();
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (octocosm[i] != pcl[i] && result.mismatches++ < 5) {
      ADD_FAILURE() << "point " << i << " (" << points.position[3 * i] << ", " << points.position[3 * i + 1] << ", "
                    << points.position[3 * i + 2] << "): octocosm leaf " << octocosm[i].Path() << ", PCL leaf "
                    << pcl[i].Path();
    }
  }
  // A face decides a point's leaf when the leaf is at least as deep as the face.
  for (std::size_t k = 0; k < face_level.size(); ++k) result.faces_deciding += octocosm[data + k].level() >= face_level[k];
  EXPECT_EQ(octocosm.back().level(), kMaxLevel) << "coincident points end at the depth limit";
  EXPECT_EQ(pcl.back(), octocosm.back());
  return result;
}

// Bound: zero mismatches. Both trees split a node holding more than 50
// points, to depth 21; PCL gets resolution size / 2^21 and the cube as its
// box, and accuracy/pcl_octree_leaves.h shows why the keys are then the same
// numbers. Hundreds of points lie exactly on cell faces, dozens of them in
// leaves at least as deep as their face (where the face decides the leaf), and
// 300 coincide, so both trees take them to the depth limit. Two cubes whose edges are not powers of two: the bounding cube
// ingest would choose (Cube::FromBounds) with its edge rounded up to a float32
// value, so that float32 points can lie on its faces; and edge 779.95978 at
// the origin, whose exact faces are all ones that a placement by the rounded
// reciprocal 1 / size put in the cell below (the bug fixed in index/cube.cc).
TEST(PclCrossCheck, EveryLeafKeyEqualsPclAdaptiveOctreeLeafEvenOnCellFaces) {
  const ParticleChunk galaxy_like = ClusteredFloatPoints(20000, 1, Cube{{-191.5, -133.25, -99.5}, 383.75, false});
  const Cube bounding = FloatBoundingCube(galaxy_like);
  int exponent = 0;
  ASSERT_NE(std::frexp(bounding.size, &exponent), 0.5) << "a dyadic cube would make faces easy";
  const KeyComparison a = CompareLeafKeys(bounding, 1);
  EXPECT_EQ(a.mismatches, 0u);
  EXPECT_GE(a.faces, 300u);
  EXPECT_GE(a.faces_deciding, 40u);

  const KeyComparison b = CompareLeafKeys(Cube{{0, 0, 0}, 779.9597778320312, false}, 2);
  EXPECT_EQ(b.mismatches, 0u);
  EXPECT_GE(b.faces_deciding, 25u);
}

// pcl::VoxelGrid, run per tile by CountVoxels, must put two points in one
// voxel exactly when octocosm puts them in one cell, at every level 0-12, on
// a dyadic cube whose origin is not at 0 and with points exactly on voxel
// faces. Bound: zero disagreements, and as many voxels as distinct cells.
TEST(PclCrossCheck, VoxelGridVoxelsAreOctocosmCellsExactly) {
  const Cube cube{{-512, 0, 1024}, 512, false};
  ParticleChunk points = ClusteredFloatPoints(30000, 4, cube);
  std::mt19937_64 rng(4);
  for (int i = 0; i < 2000; ++i) {  // on faces of level-12 cells, hence of every coarser level's
    const double edge = std::ldexp(cube.size, -12);
    const auto face = [&](int a) { return cube.origin[a] + edge * static_cast<double>(rng() % 4096); };
    AddPoint(points, face(0), face(1), face(2));
  }
  double total = 0;
  for (const double m : points.mass) total += m;
  for (int bits = 0; bits <= 12; ++bits) {
    SCOPED_TRACE("bits " + std::to_string(bits));
    const VoxelCensus census = CountVoxels(points.position, points.mass, cube, bits);
    std::set<std::uint64_t> cells;
    for (std::size_t i = 0; i < points.size(); ++i) cells.insert(cube.LeafKey(&points.position[3 * i], bits).value());
    EXPECT_EQ(census.disagreements, 0u);
    EXPECT_EQ(census.voxels(), cells.size());
    std::size_t counted = 0;
    for (const std::uint32_t c : census.count) counted += c;
    EXPECT_EQ(counted, points.size());
    EXPECT_NEAR(census.total_mass, total, 1e-9 * total);
    EXPECT_EQ(census.tiles > 1, bits > 6);
  }
  // PCL's float voxels are octocosm's cells only on a dyadic cube.
  const auto refused = [&](const Cube& other, const std::string& why) {
    try {
      CountVoxels(points.position, points.mass, other, 12);
      ADD_FAILURE() << "no error for a cube that is " << why;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  };
  refused(Cube{{-512, 0, 1024}, 600, false}, "not a power of two");
  refused(Cube{{-1023.9375, -512, 512}, 2048, false}, "not a whole number of voxel edges");
}

// The levels of one clustered data set (40000 points in 40 Gaussian halos
// and a uniform background, two species), built with capacity 300 at alpha
// 0.5 and 0, each scored against the full data next to pcl::RandomSample with
// as many points. Shared by the coverage and bias tests below.
class LevelScores : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const Cube cube{{-256, -256, -256}, 512, false};
    const ParticleChunk points = ClusteredFloatPoints(kPoints, 3, cube);
    SubtreeOptions options;
    options.capacity = 300;
    options.coarse = CoarsePoints::kSample;  // PCL's random sample checks the subselection
    std::vector<LevelSamples> trees;
    for (const double alpha : {0.5, 0.0}) {
      options.sampler.alpha = alpha;
      trees.push_back(BuildLevelSamples(points, cube, options));
    }
    levels_ = new std::vector<LevelComparison>(CompareLevels(points, trees, cube, options.capacity, 100));
  }
  static void TearDownTestSuite() {
    delete levels_;
    levels_ = nullptr;
  }

  static constexpr std::size_t kPoints = 40000;
  static inline std::vector<LevelComparison>* levels_ = nullptr;
};

// At equal point count the density-weighted levels (alpha 0.5, the default)
// keep more of the sparse voxels than a uniform random sample at every level,
// and at least 1.5 times as many at the coarse levels that hold at most half
// of the points (measured: 1.8-2.0 times), and more than mass-proportional
// sampling (alpha 0) there.
TEST_F(LevelScores, DensityWeightedLevelsKeepMoreSparseVoxelsThanPclRandomSample) {
  ASSERT_GE(levels_->size(), 5u);
  int coarse = 0;
  for (const LevelComparison& l : *levels_) {
    SCOPED_TRACE("level " + std::to_string(l.level));
    EXPECT_EQ(l.disagreements, 0u);
    const SampleScore& octocosm = l.octocosm[0];
    ASSERT_GT(l.random.sparse_voxels, 100u);
    EXPECT_GT(octocosm.sparse_voxels_kept, l.random.sparse_voxels_kept);
    if (octocosm.points <= kPoints / 2) {
      ++coarse;
      EXPECT_GE(octocosm.sparse_voxels_kept, 1.5 * l.random.sparse_voxels_kept);
      EXPECT_GT(octocosm.sparse_voxels_kept, l.octocosm[1].sparse_voxels_kept);
    }
  }
  EXPECT_GE(coarse, 2);
}

// Unbiased: in every voxel the expected estimate is the true mass, so the
// mean relative error over the voxels is zero up to noise. Bound, at every
// level, for all, sparse and dense voxels: |mean| <= 4 standard errors +
// 0.01, at alpha 0.5 and 0 (at alpha 1 the ratio estimator's bias shows:
// index/sampler.h). pcl::RandomSample's Horvitz-Thompson estimates must pass
// the same bound, or the measure itself would be wrong. Reusing one priority
// uniform at every level gave -0.78 +- 0.02 at the root.
TEST_F(LevelScores, VoxelMassEstimatesAreUnbiased) {
  ASSERT_GE(levels_->size(), 5u);
  for (const LevelComparison& l : *levels_) {
    for (int k = 0; k < 3; ++k) {
      const SampleScore& score = k < 2 ? l.octocosm[k] : l.random;
      const char* name = k == 0 ? "alpha 0.5" : k == 1 ? "alpha 0" : "pcl::RandomSample";
      for (const auto* d : {&score.all, &score.sparse, &score.dense}) {
        const char* group = d == &score.all ? "all" : d == &score.sparse ? "sparse" : "dense";
        if (d->voxels < 20) continue;
        EXPECT_LE(std::fabs(d->mean), 4 * d->standard_error + 0.01)
            << name << ", level " << l.level << ", " << group << " voxels: mean relative error " << d->mean << " +- "
            << d->standard_error << " over " << d->voxels;
      }
    }
  }
}

}  // namespace
}  // namespace octocosm::accuracy
