#include "index/aggregator.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "index/block_codec.h"
#include "index/subtree_builder.h"
#include "storage/error.h"

namespace octocosm {
namespace {

const Cube kCube{{-50, -50, -50}, 100, false};

// Clumps on a uniform background, with IDs, velocities and (for some
// particles) given smoothing lengths.
ParticleChunk Clumpy(std::uint64_t seed, std::size_t n) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-50, 50);
  std::lognormal_distribution<double> mass(0, 1);
  std::vector<std::array<double, 4>> clumps;
  for (int k = 0; k < 6; ++k) clumps.push_back({u(rng) * 0.8, u(rng) * 0.8, u(rng) * 0.8, std::exp2(-static_cast<double>(k)) * 3});
  ParticleChunk c;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = rng() % 10;
    for (int a = 0; a < 3; ++a) {
      const double x = k < clumps.size() ? std::normal_distribution<double>(clumps[k][a], clumps[k][3])(rng) : u(rng);
      c.position.push_back(std::clamp(x, -50.0, 49.999));
    }
    c.mass.push_back(mass(rng));
    c.type.push_back(static_cast<std::uint8_t>(i % 3));
    c.id.push_back(10 * i + 3);
    for (int a = 0; a < 3; ++a) c.velocity.push_back(static_cast<float>(std::normal_distribution<double>(0, 100)(rng)));
    c.smoothing.push_back(static_cast<float>(0.05 + 0.5 * std::abs(std::normal_distribution<double>(0, 1)(rng))));
  }
  return c;
}

TEST(ClusterPopulation, EveryPointInOneClusterOfOneOctantAtMostCapacityClusters) {
  const ParticleChunk c = Clumpy(1, 20000);
  std::vector<GridPoint> grid;
  for (std::size_t i = 0; i < c.size(); ++i) grid.push_back(kCube.FinestGridCoords(&c.position[3 * i]));
  for (const std::size_t capacity : {8u, 100u, 1000u, 19999u, 50000u}) {
    const Clusters clusters = ClusterPopulation(grid, c.mass, {}, NodeKey::Root(), capacity);
    ASSERT_LE(clusters.size(), capacity);
    if (capacity >= c.size()) {
      EXPECT_EQ(clusters.size(), c.size()) << "room for every point: each its own cluster";
    } else {
      EXPECT_GT(clusters.size(), capacity - 8) << "splits go on while they fit";
    }
    std::vector<int> seen(c.size(), 0);
    int last_octant = 0;
    for (std::size_t k = 0; k < clusters.size(); ++k) {
      const int octant = OctantAt(grid[clusters.member[clusters.begin[k]]], 0);
      EXPECT_GE(octant, last_octant) << "clusters ordered by octant";
      last_octant = octant;
      for (std::uint32_t m = clusters.begin[k]; m < clusters.begin[k + 1]; ++m) {
        ++seen[clusters.member[m]];
        EXPECT_EQ(OctantAt(grid[clusters.member[m]], 0), octant);
      }
    }
    EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), static_cast<long>(c.size()));
  }
  EXPECT_THROW(ClusterPopulation(grid, c.mass, {}, NodeKey::Root(), 7), Error);
  EXPECT_THROW(ClusterPopulation(grid, c.mass, c.type, NodeKey::Root(), 23), Error) << "three types need 24";
}

TEST(ClusterPopulation, TheHeaviestRegionsAreCutFinest) {
  // A heavy clump and a light background of as many points: the clump gets
  // most of the clusters.
  std::mt19937_64 rng(2);
  std::normal_distribution<double> clump(10, 0.5);
  std::uniform_real_distribution<double> u(-50, 50);
  std::vector<GridPoint> grid;
  std::vector<double> weight;
  std::vector<bool> in_clump;
  for (int i = 0; i < 20000; ++i) {
    const bool heavy = i % 2 == 0;
    double p[3];
    for (double& x : p) x = heavy ? clump(rng) : u(rng);
    grid.push_back(kCube.FinestGridCoords(p));
    weight.push_back(heavy ? 10.0 : 1.0);
    in_clump.push_back(heavy);
  }
  const Clusters clusters = ClusterPopulation(grid, weight, {}, NodeKey::Root(), 1000);
  std::size_t clump_clusters = 0;
  for (std::size_t k = 0; k < clusters.size(); ++k) clump_clusters += in_clump[clusters.member[clusters.begin[k]]];
  EXPECT_GT(clump_clusters, clusters.size() * 3 / 4);
}

struct Moments {
  double mass = 0;
  std::array<double, 3> type_mass{};  // Clumpy's types 0, 1, 2
  std::array<double, 3> first{};     // sum of w x
  double second = 0;                 // sum of w (|x|^2 + 3 kernel variance)
  std::array<double, 3> momentum{};  // sum of w v
  void Add(const double* x, double w, double h, const float* v, std::uint8_t type) {
    mass += w;
    type_mass[type] += w;
    for (int a = 0; a < 3; ++a) {
      first[a] += w * x[a];
      second += w * x[a] * x[a];
      momentum[a] += w * v[a];
    }
    second += w * 3 * KernelVariance(h);
  }
};

// Every inner node's clusters keep, in each octant, the mass (per particle
// type too), the centre of mass, the second moment (the members' spread and their own blobs') and the
// momentum of the particles below it: they move where the particles' mass
// goes and blur it as much as the particles' blobs do together.
TEST(AggregateParent, ClustersKeepEachOctantsMassCentreSpreadAndMomentum) {
  const ParticleChunk input = Clumpy(3, 30000);
  SubtreeOptions options;
  options.capacity = 300;
  ASSERT_EQ(options.coarse, CoarsePoints::kClusters) << "clusters are the default";
  std::map<NodeKey, NodePoints> nodes;
  BuildSubtree(input, NodeKey::Root(), kCube, options, [&](NodeKey key, const NodePoints& p) { nodes[key] = p; });
  // The particles' moments per node, from the leaves up.
  std::map<NodeKey, Moments> truth;
  for (std::size_t i = 0; i < input.size(); ++i) {
    for (int level = 0; level <= kMaxLevel; ++level) {
      const NodeKey key = kCube.LeafKey(&input.position[3 * i], level);
      if (!nodes.count(key)) break;
      truth[key].Add(&input.position[3 * i], input.mass[i], input.smoothing[i], &input.velocity[3 * i], input.type[i]);
    }
  }
  std::size_t inner = 0;
  for (const auto& [key, points] : nodes) {
    bool leaf = true;
    for (int o = 0; o < 8; ++o) leaf = leaf && !nodes.count(key.Child(o));
    if (leaf) continue;
    ++inner;
    EXPECT_LE(points.size(), options.capacity) << key.Path();
    for (int o = 0; o < 8; ++o) {
      Moments got;
      for (std::uint32_t i = points.octant_offsets[o]; i < points.octant_offsets[o + 1]; ++i) {
        ASSERT_TRUE(kCube.Holds(key.Child(o), &points.position[3 * i])) << key.Path() << " octant " << o;
        got.Add(&points.position[3 * i], points.weight[i], points.smoothing[i], &points.velocity[3 * i], points.type[i]);
      }
      const NodeKey child = key.Child(o);
      if (!truth.count(child)) {
        EXPECT_EQ(got.mass, 0) << child.Path();
        continue;
      }
      const Moments& want = truth.at(child);
      SCOPED_TRACE(child.Path());
      EXPECT_NEAR(got.mass / want.mass, 1, 1e-12);
      for (int t = 0; t < 3; ++t) EXPECT_NEAR(got.type_mass[t], want.type_mass[t], 1e-12 * want.mass) << "type " << t;
      for (int a = 0; a < 3; ++a) {
        EXPECT_NEAR(got.first[a] / want.mass, want.first[a] / want.mass, 1e-9);
        EXPECT_NEAR(got.momentum[a] / want.mass, want.momentum[a] / want.mass, 1e-3);  // float velocities
      }
      EXPECT_NEAR(got.second / want.second, 1, 1e-9);
    }
  }
  EXPECT_GT(inner, 5u);
}

// Chunked as the out-of-core pipeline builds, the clusters come out the
// same, block for block.
TEST(AggregateParent, TopLevelsGiveTheBlocksOfOneBuild) {
  ParticleChunk input = Clumpy(5, 40000);
  input.smoothing.clear();
  SubtreeOptions options;
  options.capacity = 200;
  std::map<NodeKey, NodePoints> whole, pieces;
  BuildSubtree(input, NodeKey::Root(), kCube, options, [&](NodeKey key, const NodePoints& p) { whole[key] = p; });
  std::map<NodeKey, ParticleChunk> chunks;
  for (std::size_t i = 0; i < input.size(); ++i) {
    ParticleChunk& to = chunks[kCube.LeafKey(&input.position[3 * i], 2)];
    to.position.insert(to.position.end(), &input.position[3 * i], &input.position[3 * i] + 3);
    to.velocity.insert(to.velocity.end(), &input.velocity[3 * i], &input.velocity[3 * i] + 3);
    to.mass.push_back(input.mass[i]);
    to.id.push_back(input.id[i]);
    to.type.push_back(input.type[i]);
  }
  std::vector<RegionRoot> roots;
  const NodeSink sink = [&](NodeKey key, const NodePoints& p) { pieces[key] = p; };
  for (auto& [key, chunk] : chunks) roots.push_back({key, BuildSubtree(chunk, key, kCube, options, sink)});
  BuildTopLevels(std::move(roots), kCube, options, sink);
  ASSERT_EQ(pieces.size(), whole.size());
  for (const auto& [key, points] : whole) {
    ASSERT_TRUE(pieces.count(key)) << key.Path();
    EXPECT_EQ(EncodeBlock(pieces.at(key), key, kCube), EncodeBlock(points, key, kCube)) << key.Path();
  }
}

// Sampling keeps particles; clusters stand for many: at the same count the
// clusters' points are not the particles'.
TEST(AggregateParent, SampleAndClustersDiffer) {
  const ParticleChunk input = Clumpy(7, 5000);
  SubtreeOptions clusters;
  clusters.capacity = 100;
  SubtreeOptions sample = clusters;
  sample.coarse = CoarsePoints::kSample;
  NodePoints a = BuildSubtree(input, NodeKey::Root(), kCube, clusters, [](NodeKey, const NodePoints&) {});
  NodePoints b = BuildSubtree(input, NodeKey::Root(), kCube, sample, [](NodeKey, const NodePoints&) {});
  std::set<std::array<double, 3>> particles;
  for (std::size_t i = 0; i < input.size(); ++i) particles.insert({input.position[3 * i], input.position[3 * i + 1], input.position[3 * i + 2]});
  std::size_t a_particles = 0, b_particles = 0;
  for (std::size_t i = 0; i < a.size(); ++i) a_particles += particles.count({a.position[3 * i], a.position[3 * i + 1], a.position[3 * i + 2]});
  for (std::size_t i = 0; i < b.size(); ++i) b_particles += particles.count({b.position[3 * i], b.position[3 * i + 1], b.position[3 * i + 2]});
  EXPECT_EQ(b_particles, b.size());
  EXPECT_LT(a_particles, a.size() / 2);
}

}  // namespace
}  // namespace octocosm
