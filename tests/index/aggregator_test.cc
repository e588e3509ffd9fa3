#include "index/aggregator.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "base/error.h"
#include "index/block_codec.h"
#include "index/cluster_shape.h"
#include "index/subtree_builder.h"

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
    const Clusters clusters = ClusterPopulation(grid, c.mass, {}, {}, NodeKey::Root(), capacity);
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
  EXPECT_THROW(ClusterPopulation(grid, c.mass, {}, {}, NodeKey::Root(), 7), Error);
  EXPECT_THROW(ClusterPopulation(grid, c.mass, {}, c.type, NodeKey::Root(), 23), Error) << "three types need 24";
  EXPECT_THROW(ClusterPopulation(grid, c.mass, std::vector<double>(3, 0.0), {}, NodeKey::Root(), 100), Error)
      << "a blob variance for every point or none";
}

// `count` points of weight `w` around `centre`: a Gaussian of `sigma` per
// axis, or along `direction` only when one is given (a filament).
struct Population {
  std::vector<GridPoint> grid;
  std::vector<double> weight, own_variance;
  std::vector<int> group;
  std::vector<double> along;  // position along the filament's direction

  void Add(int g, std::size_t count, double w, const std::array<double, 3>& centre, double sigma,
           std::uint64_t seed, double own = 0, const std::array<double, 3>* direction = nullptr) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> normal(0, sigma);
    for (std::size_t i = 0; i < count; ++i) {
      double p[3];
      const double t = normal(rng);
      for (int a = 0; a < 3; ++a) p[a] = std::clamp(centre[a] + (direction ? t * (*direction)[a] : normal(rng)), -49.9, 49.9);
      grid.push_back(kCube.FinestGridCoords(p));
      weight.push_back(w);
      own_variance.push_back(own);
      group.push_back(g);
      along.push_back(t);
    }
  }
  // Clusters of each group.
  std::map<int, std::size_t> ClustersOf(const Clusters& clusters) const {
    std::map<int, std::size_t> count;
    for (std::size_t k = 0; k < clusters.size(); ++k) ++count[group[clusters.member[clusters.begin[k]]]];
    return count;
  }
};

TEST(ClusterPopulation, SpreadOutMassGetsTheClustersACompactClumpDoesNot) {
  // Two clumps of equal mass and count. At capacity 1000 the root's point
  // spacing is 100 / 10 and a pixel, where the root is drawn, an eighth of
  // that (1.25): the clump of sigma 0.05 stays within a pixel, the one of
  // sigma 5 spans many.
  Population p;
  p.Add(0, 10000, 1.0, {20, 20, 20}, 0.05, 1);
  p.Add(1, 10000, 1.0, {-20, -20, -20}, 5, 2);
  const Clusters clusters = ClusterPopulation(p.grid, p.weight, {}, {}, NodeKey::Root(), 1000);
  const auto count = p.ClustersOf(clusters);
  EXPECT_EQ(clusters.size(), 1000u);
  EXPECT_LT(count.at(0), 50u);
  EXPECT_GT(count.at(1), 950u);
}

TEST(ClusterPopulation, OfEqualSpreadTheHeavierIsCutFiner) {
  Population p;
  p.Add(0, 10000, 10.0, {20, 20, 20}, 5, 3);
  p.Add(1, 10000, 1.0, {-20, -20, -20}, 5, 4);
  const auto count = p.ClustersOf(ClusterPopulation(p.grid, p.weight, {}, {}, NodeKey::Root(), 1000));
  EXPECT_GT(count.at(0), 3 * count.at(1));
}

TEST(ClusterPopulation, MembersWhoseOwnBlobsOverlapAreCutLess) {
  // The same clump twice, once of points whose blobs (variance 25 per axis,
  // in node edges 0.0025) are wider than the clump itself.
  Population p;
  p.Add(0, 10000, 1.0, {20, 20, 20}, 2, 5, 0.0);
  p.Add(1, 10000, 1.0, {-20, -20, -20}, 2, 5, 0.0025);
  const auto count = p.ClustersOf(ClusterPopulation(p.grid, p.weight, p.own_variance, {}, NodeKey::Root(), 1000));
  EXPECT_GT(count.at(0), 2 * count.at(1));
}

TEST(ClusterPopulation, AFilamentIsCutAcrossItsLength) {
  // A filament along a diagonal inside one octant, 0.3 wide, cut into
  // pieces longer than wide: each cluster is a piece of it, so the clusters' ranges along it overlap by no more
  // than the principal axes' tilt makes of its width (cubes would cut it
  // obliquely, their ranges overlapping by about its width).
  Population p;
  const double r = 1 / std::sqrt(3.0);
  const std::array<double, 3> direction = {r, r, -r};
  p.Add(0, 5000, 1.0, {25, 25, 25}, 5, 6, 0.0, &direction);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> across(0, 0.3);
  for (std::size_t i = 0; i < p.grid.size(); ++i) {
    double x[3];
    for (int a = 0; a < 3; ++a) x[a] = 25 + p.along[i] * direction[a] + across(rng);
    p.grid[i] = kCube.FinestGridCoords(x);
    p.along[i] = (x[0] - 25) * direction[0] + (x[1] - 25) * direction[1] + (x[2] - 25) * direction[2];
  }
  const Clusters clusters = ClusterPopulation(p.grid, p.weight, {}, {}, NodeKey::Root(), 12);
  ASSERT_EQ(clusters.size(), 12u);
  std::vector<std::pair<double, double>> ranges;
  for (std::size_t k = 0; k < clusters.size(); ++k) {
    double lo = INFINITY, hi = -INFINITY;
    for (std::uint32_t m = clusters.begin[k]; m < clusters.begin[k + 1]; ++m) {
      lo = std::min(lo, p.along[clusters.member[m]]);
      hi = std::max(hi, p.along[clusters.member[m]]);
    }
    ranges.emplace_back(lo, hi);
  }
  std::sort(ranges.begin(), ranges.end());
  double overlap = 0;
  for (std::size_t k = 1; k < ranges.size(); ++k) overlap = std::max(overlap, ranges[k - 1].second - ranges[k].first);
  EXPECT_LT(overlap, 0.05);
}

TEST(ClusterPopulation, TheSamePopulationGivesTheSameClusters) {
  const ParticleChunk c = Clumpy(7, 20000);
  std::vector<GridPoint> grid;
  for (std::size_t i = 0; i < c.size(); ++i) grid.push_back(kCube.FinestGridCoords(&c.position[3 * i]));
  std::vector<double> own;
  for (const float h : c.smoothing) own.push_back(KernelVariance(h / kCube.size));
  const Clusters a = ClusterPopulation(grid, c.mass, own, c.type, NodeKey::Root(), 999);
  const Clusters b = ClusterPopulation(grid, c.mass, own, c.type, NodeKey::Root(), 999);
  EXPECT_EQ(a.member, b.member);
  EXPECT_EQ(a.begin, b.begin);
  for (std::size_t k = 0; k < a.size(); ++k) {
    for (std::uint32_t m = a.begin[k] + 1; m < a.begin[k + 1]; ++m) {
      ASSERT_LT(a.member[m - 1], a.member[m]) << "members in ascending order";
      ASSERT_EQ(c.type[a.member[m]], c.type[a.member[a.begin[k]]]) << "one type a cluster";
    }
  }
}

struct Moments {
  double mass = 0;
  std::array<double, 3> type_mass{};  // Clumpy's types 0, 1, 2
  std::array<double, 3> first{};     // sum of w x
  double second = 0;                 // sum of w (|x|^2 + 3 kernel variance)
  std::array<double, 3> momentum{};  // sum of w v
  double velocity_second = 0;        // sum of w (|v|^2 + 3 sigma^2): twice the kinetic energy
  void Add(const double* x, double w, double h, const float* v, std::uint8_t type, double sigma = 0) {
    mass += w;
    type_mass[type] += w;
    for (int a = 0; a < 3; ++a) {
      first[a] += w * x[a];
      second += w * x[a] * x[a];
      momentum[a] += w * v[a];
      velocity_second += w * double{v[a]} * v[a];
    }
    second += w * 3 * KernelVariance(h);
    velocity_second += w * 3 * sigma * sigma;
  }
};

// Every inner node's clusters keep, in each octant, the mass (per particle
// type too), the centre of mass, the second moment (the members' spread and their own blobs') and the
// momentum of the particles below it: they move where the particles' mass
// goes and blur it as much as the particles' blobs do together. With their
// velocity dispersions they keep the second moment of the velocities too
// (the kinetic energy), however many levels of clusters lie between.
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
    if (leaf) {
      EXPECT_TRUE(points.velocity_dispersion.empty()) << key.Path() << ": a leaf's points are particles";
      continue;
    }
    ++inner;
    EXPECT_LE(points.size(), options.capacity) << key.Path();
    ASSERT_EQ(points.velocity_dispersion.size(), points.size()) << key.Path();
    for (int o = 0; o < 8; ++o) {
      Moments got;
      for (std::uint32_t i = points.octant_offsets[o]; i < points.octant_offsets[o + 1]; ++i) {
        ASSERT_TRUE(kCube.Holds(key.Child(o), &points.position[3 * i])) << key.Path() << " octant " << o;
        ASSERT_GE(points.velocity_dispersion[i], 0.0f);
        got.Add(&points.position[3 * i], points.weight[i], points.smoothing[i], &points.velocity[3 * i], points.type[i],
                points.velocity_dispersion[i]);
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
      EXPECT_NEAR(got.velocity_second / want.velocity_second, 1, 1e-5);  // float velocities and dispersions
    }
  }
  EXPECT_GT(inner, 5u);
}

// `count` particles at one place (a cluster that no split can part), with
// the given masses and velocities, as a chunk of one type.
ParticleChunk Coincident(const std::array<double, 3>& at, const std::vector<double>& mass,
                         const std::vector<std::array<float, 3>>& velocity, std::uint64_t first_id) {
  ParticleChunk c;
  for (std::size_t i = 0; i < mass.size(); ++i) {
    c.position.insert(c.position.end(), at.begin(), at.end());
    c.mass.push_back(mass[i]);
    c.type.push_back(0);
    c.id.push_back(first_id + i);
    c.velocity.insert(c.velocity.end(), velocity[i].begin(), velocity[i].end());
  }
  return c;
}

// sigma^2 = sum w |v - vbar|^2 / (3 W) over the particles, in double.
double DirectDispersion(const std::vector<const ParticleChunk*>& chunks) {
  double mass = 0, mean[3] = {0, 0, 0};
  for (const ParticleChunk* c : chunks) {
    for (std::size_t i = 0; i < c->size(); ++i) {
      mass += c->mass[i];
      for (int a = 0; a < 3; ++a) mean[a] += c->mass[i] * c->velocity[3 * i + a];
    }
  }
  for (double& m : mean) m /= mass;
  double sum = 0;
  for (const ParticleChunk* c : chunks) {
    for (std::size_t i = 0; i < c->size(); ++i) {
      for (int a = 0; a < 3; ++a) sum += c->mass[i] * (c->velocity[3 * i + a] - mean[a]) * (c->velocity[3 * i + a] - mean[a]);
    }
  }
  return std::sqrt(sum / (3 * mass));
}

// Two groups of coincident particles, each the only points of a leaf: the
// root has one cluster of each, with the dispersion worked out by hand.
TEST(AggregateParent, VelocityDispersionOfSmallClustersByHand) {
  SubtreeOptions options;
  options.capacity = 8;
  // Masses 1, 1, 2 at velocities (1,0,0), (-1,0,0), (0,2,0): mean (0,1,0),
  // squared offsets 2, 2, 1, so sigma^2 = (2 + 2 + 2 * 1) / (3 * 4) = 1/2.
  const ParticleChunk slow = Coincident({-25, -25, -25}, {1, 1, 2}, {{1, 0, 0}, {-1, 0, 0}, {0, 2, 0}}, 1);
  // Masses 3, 1 at (10,0,0), (-2,4,0): mean (7,1,0), squared offsets 10 and
  // 90, so sigma^2 = (3 * 10 + 90) / (3 * 4) = 10.
  const ParticleChunk fast = Coincident({25, 25, 25}, {3, 1}, {{10, 0, 0}, {-2, 4, 0}}, 10);
  std::map<NodeKey, NodePoints> nodes;
  const NodeSink sink = [&](NodeKey key, const NodePoints& p) { nodes[key] = p; };
  const NodeKey r0 = NodeKey::Root().Child(0), r7 = NodeKey::Root().Child(7);
  std::vector<RegionRoot> regions;
  regions.push_back({r0, BuildSubtree(slow, r0, kCube, options, sink)});
  regions.push_back({r7, BuildSubtree(fast, r7, kCube, options, sink)});
  const NodePoints root = BuildTopLevels(std::move(regions), kCube, options, sink);
  EXPECT_TRUE(nodes.at(r0).velocity_dispersion.empty()) << "a leaf's points are particles";
  EXPECT_TRUE(nodes.at(r7).velocity_dispersion.empty());
  ASSERT_EQ(root.size(), 2u);
  ASSERT_EQ(root.velocity_dispersion.size(), 2u);
  EXPECT_FLOAT_EQ(root.velocity_dispersion[0], std::sqrt(0.5f));
  EXPECT_FLOAT_EQ(root.velocity_dispersion[1], std::sqrt(10.0f));
  EXPECT_EQ(root.velocity, (std::vector<float>{0, 1, 0, 7, 1, 0}));
  EXPECT_EQ(root.weight, (std::vector<double>{4, 4}));
  // As the direct computation says.
  EXPECT_FLOAT_EQ(root.velocity_dispersion[0], static_cast<float>(DirectDispersion({&slow})));
  EXPECT_FLOAT_EQ(root.velocity_dispersion[1], static_cast<float>(DirectDispersion({&fast})));
  // A single particle's cluster: 0.
  const ParticleChunk one = Coincident({-25, -25, -25}, {2}, {{5, 6, 7}}, 20);
  std::vector<RegionRoot> single;
  single.push_back({r0, BuildSubtree(one, r0, kCube, options, sink)});
  single.push_back({r7, BuildSubtree(fast, r7, kCube, options, sink)});
  EXPECT_EQ(BuildTopLevels(std::move(single), kCube, options, sink).velocity_dispersion[0], 0.0f);
}

// Siblings may differ in carrying dispersions (a leaf beside a node of
// clusters, above), but a child's dispersions must be one per point and go
// with velocities.
TEST(AggregateParent, ChildDispersionsThatDoNotFitTheirPointsAreRejected) {
  SubtreeOptions options;
  options.capacity = 8;
  const NodeKey r0 = NodeKey::Root().Child(0), r7 = NodeKey::Root().Child(7);
  const auto noop = [](NodeKey, const NodePoints&) {};
  const NodePoints slow =
      BuildSubtree(Coincident({-25, -25, -25}, {1, 1, 2}, {{1, 0, 0}, {-1, 0, 0}, {0, 2, 0}}, 1), r0, kCube, options, noop);
  const NodePoints fast = BuildSubtree(Coincident({25, 25, 25}, {3, 1}, {{10, 0, 0}, {-2, 4, 0}}, 10), r7, kCube, options, noop);
  const auto expect_rejected = [&](NodePoints child, const std::string& message) {
    try {
      BuildTopLevels({{r0, std::move(child)}, {r7, fast}}, kCube, options, noop);
      ADD_FAILURE() << message;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
    }
  };
  NodePoints wrong_size = slow;
  wrong_size.velocity_dispersion = {1, 2};
  expect_rejected(wrong_size, "child r0 has 2 velocity dispersions for 3 points");
  NodePoints without_velocity = slow;
  without_velocity.velocity.clear();
  without_velocity.velocity_dispersion = {1, 2, 3};
  NodePoints fast_without_velocity = fast;
  fast_without_velocity.velocity.clear();
  try {
    BuildTopLevels({{r0, without_velocity}, {r7, fast_without_velocity}}, kCube, options, noop);
    ADD_FAILURE() << "dispersions without velocities";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("and no velocities"), std::string::npos) << e.what();
  }
  // Members with dispersions 1, 2, 3 of their own (as if each were a
  // cluster): sigma^2 = (6 + 3 * (1 * 1 + 1 * 4 + 2 * 9)) / (3 * 4) = 6.25.
  NodePoints fitting = slow;
  fitting.velocity_dispersion = {1, 2, 3};
  const NodePoints root = BuildTopLevels({{r0, fitting}, {r7, fast}}, kCube, options, noop);
  ASSERT_EQ(root.velocity_dispersion.size(), 2u);
  EXPECT_FLOAT_EQ(root.velocity_dispersion[0], 2.5f);
}

// A cluster of clusters: the root's cluster of octant 0 stands for the
// eight clusters of r0, each a group of coincident particles with its own
// dispersion (and a bulk flow the float velocities must carry). Its
// dispersion, computed through theirs, is the one over all the particles.
TEST(AggregateParent, DispersionThroughChildClustersIsTheDirectOneOverTheirParticles) {
  SubtreeOptions options;
  options.capacity = 8;
  std::mt19937_64 rng(11);
  std::lognormal_distribution<double> mass(0, 1);
  std::normal_distribution<float> velocity(0, 80);
  const NodeKey r0 = NodeKey::Root().Child(0), r7 = NodeKey::Root().Child(7);
  std::vector<ParticleChunk> groups;
  std::vector<NodeKey> group_keys;
  for (int octant = 0; octant < 8; ++octant) {
    const NodeKey key = r0.Child(octant);
    const NodeCube cell = kCube.NodeCubeOf(key);
    const std::size_t count = 2 + rng() % 6;  // at most the capacity: a leaf
    std::vector<double> masses;
    std::vector<std::array<float, 3>> velocities;
    for (std::size_t i = 0; i < count; ++i) {
      masses.push_back(mass(rng));
      // Each group its own mean too, so the groups' offsets count.
      velocities.push_back({300 + 20.0f * static_cast<float>(octant) + velocity(rng), -150 + velocity(rng), velocity(rng)});
    }
    const double h = cell.size / 2;
    groups.push_back(Coincident({cell.origin[0] + h, cell.origin[1] + h, cell.origin[2] + h}, masses, velocities,
                                100 * static_cast<std::uint64_t>(octant)));
    group_keys.push_back(key);
  }
  const ParticleChunk far = Coincident({25, 25, 25}, {1, 2}, {{0, 0, 0}, {3, 3, 3}}, 5000);
  std::map<NodeKey, NodePoints> nodes;
  const NodeSink sink = [&](NodeKey key, const NodePoints& p) { nodes[key] = p; };
  std::vector<RegionRoot> regions;
  for (std::size_t g = 0; g < groups.size(); ++g) {
    regions.push_back({group_keys[g], BuildSubtree(groups[g], group_keys[g], kCube, options, sink)});
  }
  regions.push_back({r7, BuildSubtree(far, r7, kCube, options, sink)});  // a leaf beside an inner node
  // A particle in each of the root's other octants: the root starts with
  // as many cells as its capacity, so r0 makes one cluster there.
  for (int octant = 1; octant < 7; ++octant) {
    const NodeKey key = NodeKey::Root().Child(octant);
    const NodeCube cell = kCube.NodeCubeOf(key);
    const double h = cell.size / 2;
    regions.push_back({key, BuildSubtree(Coincident({cell.origin[0] + h, cell.origin[1] + h, cell.origin[2] + h}, {1},
                                                    {{0, 0, 0}}, 9000 + static_cast<std::uint64_t>(octant)),
                                         key, kCube, options, sink)});
  }
  const NodePoints root = BuildTopLevels(std::move(regions), kCube, options, sink);

  // r0: one cluster per group.
  const NodePoints& parent = nodes.at(r0);
  ASSERT_EQ(parent.size(), 8u);
  ASSERT_EQ(parent.velocity_dispersion.size(), 8u);
  for (int octant = 0; octant < 8; ++octant) {
    EXPECT_NEAR(parent.velocity_dispersion[octant], DirectDispersion({&groups[octant]}),
                1e-6 * DirectDispersion({&groups[octant]}))
        << octant;
  }
  // The root: all of r0 in one cluster, r7's leaf in another.
  ASSERT_EQ(root.size(), 8u);
  ASSERT_EQ(root.octant_offsets[1], 1u);
  std::vector<const ParticleChunk*> all;
  for (const ParticleChunk& g : groups) all.push_back(&g);
  const double direct = DirectDispersion(all);
  EXPECT_NEAR(root.velocity_dispersion[0], direct, 1e-5 * direct);
  EXPECT_FLOAT_EQ(root.velocity_dispersion[7], static_cast<float>(DirectDispersion({&far})));
  // The members' own dispersions matter: without them the root would see
  // the spread between the groups' means only.
  double between = 0, total_mass = 0, mean[3] = {0, 0, 0};
  for (std::size_t k = 0; k < parent.size(); ++k) {
    total_mass += parent.weight[k];
    for (int a = 0; a < 3; ++a) mean[a] += parent.weight[k] * parent.velocity[3 * k + a];
  }
  for (double& m : mean) m /= total_mass;
  for (std::size_t k = 0; k < parent.size(); ++k) {
    for (int a = 0; a < 3; ++a) between += parent.weight[k] * std::pow(parent.velocity[3 * k + a] - mean[a], 2);
  }
  EXPECT_LT(std::sqrt(between / (3 * total_mass)), 0.9 * direct);
}

// C = sum w ((x - mean)(x - mean)^T + own blob's covariance) / W over points
// with round blobs, as (xx, yy, zz, xy, xz, yz).
SymmetricMatrix DirectCovariance(const std::vector<const NodePoints*>& sets) {
  double mass = 0, mean[3] = {0, 0, 0};
  for (const NodePoints* p : sets) {
    for (std::size_t i = 0; i < p->size(); ++i) {
      mass += p->weight[i];
      for (int a = 0; a < 3; ++a) mean[a] += p->weight[i] * p->position[3 * i + a];
    }
  }
  for (double& m : mean) m /= mass;
  SymmetricMatrix c{};
  for (const NodePoints* p : sets) {
    for (std::size_t i = 0; i < p->size(); ++i) {
      double d[3];
      for (int a = 0; a < 3; ++a) d[a] = p->position[3 * i + a] - mean[a];
      const double own = KernelVariance(p->smoothing[i]);
      const double outer[6] = {d[0] * d[0] + own, d[1] * d[1] + own, d[2] * d[2] + own, d[0] * d[1], d[0] * d[2], d[1] * d[2]};
      for (int k = 0; k < 6; ++k) c[k] += p->weight[i] * outer[k];
    }
  }
  for (double& x : c) x /= mass;
  return c;
}

// Normalized to trace 3 and pulled towards the sphere, as stored.
SymmetricMatrix ExpectedShape(const SymmetricMatrix& c) {
  const double mean = (c[0] + c[1] + c[2]) / 3;
  SymmetricMatrix s{};
  for (int k = 0; k < 6; ++k) s[k] = (1 - kShapeFloor) * c[k] / mean + kShapeFloor * (k < 3 ? 1 : 0);
  return s;
}

// Clusters keep their members' covariance as a shape: a leaf of particles on
// a segment gives a cluster stretched along it, and a cluster of such
// clusters has the covariance of all the particles below it, its members'
// shapes included (within the codes' rounding: 1/85 on the diagonal, 3/254
// off it, and their effect through the members).
TEST(AggregateParent, ShapesKeepTheCovarianceThroughClustersOfClusters) {
  SubtreeOptions options;
  options.capacity = 8;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  const NodeKey r0 = NodeKey::Root().Child(0), r7 = NodeKey::Root().Child(7);
  std::map<NodeKey, NodePoints> nodes;
  const NodeSink sink = [&](NodeKey key, const NodePoints& p) { nodes[key] = p; };
  std::vector<RegionRoot> regions;
  std::vector<NodeKey> leaves;
  for (int octant = 0; octant < 8; ++octant) {
    const NodeKey key = r0.Child(octant);
    const NodeCube cell = kCube.NodeCubeOf(key);
    // Up to 8 particles (a leaf) on a segment through the cell, each octant
    // along another direction.
    const double direction[3] = {1.0 + octant % 2, 0.3 * (octant / 2 % 2), -0.5 * (octant / 4)};
    ParticleChunk c;
    for (int i = 0; i < 8; ++i) {
      const double t = u(rng) - 0.5;
      for (int a = 0; a < 3; ++a) c.position.push_back(cell.origin[a] + cell.size * (0.5 + 0.4 * t * direction[a] / 2));
      c.mass.push_back(0.5 + u(rng));
      c.type.push_back(0);
      c.smoothing.push_back(static_cast<float>(0.01 * cell.size));
    }
    regions.push_back({key, BuildSubtree(c, key, kCube, options, sink)});
    leaves.push_back(key);
  }
  ParticleChunk far;
  far.position = {25, 25, 25};
  far.mass = {1};
  far.type = {0};
  far.smoothing = {0.5f};
  regions.push_back({r7, BuildSubtree(far, r7, kCube, options, sink)});
  // A particle in each of the root's other octants: the root starts with
  // as many cells as its capacity, so r0 makes one cluster there.
  for (int octant = 1; octant < 7; ++octant) {
    const NodeKey key = NodeKey::Root().Child(octant);
    const NodeCube cell = kCube.NodeCubeOf(key);
    ParticleChunk one;
    for (int a = 0; a < 3; ++a) one.position.push_back(cell.origin[a] + cell.size / 2);
    one.mass = {1};
    one.type = {0};
    one.smoothing = {0.5f};
    regions.push_back({key, BuildSubtree(one, key, kCube, options, sink)});
  }
  const NodePoints root = BuildTopLevels(std::move(regions), kCube, options, sink);

  const NodePoints& parent = nodes.at(r0);
  ASSERT_EQ(parent.size(), 8u);
  ASSERT_EQ(parent.shape.size(), 6 * parent.size());
  for (int octant = 0; octant < 8; ++octant) {
    SCOPED_TRACE(octant);
    const NodePoints& leaf = nodes.at(leaves[octant]);
    EXPECT_TRUE(leaf.shape.empty()) << "a leaf's points are particles, round";
    const SymmetricMatrix want = ExpectedShape(DirectCovariance({&leaf}));
    const SymmetricMatrix got = DecodeShape(ShapeCodeAt(parent.shape, static_cast<std::size_t>(octant)));
    for (int k = 0; k < 6; ++k) EXPECT_NEAR(got[k], want[k], 0.5 / 85 + 1e-9) << "entry " << k;
    EXPECT_GT(got[0], 1.5) << "stretched along x";
  }
  // The root: r0's clusters in one, r7's particle (round) in another.
  ASSERT_EQ(root.size(), 8u);
  std::vector<const NodePoints*> all;
  for (const NodeKey& key : leaves) all.push_back(&nodes.at(key));
  const SymmetricMatrix want = ExpectedShape(DirectCovariance(all));
  const SymmetricMatrix got = DecodeShape(ShapeCodeAt(root.shape, 0));
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(got[k], want[k], 0.03) << "entry " << k;
  const SymmetricMatrix single = DecodeShape(ShapeCodeAt(root.shape, 7));
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(single[k], k < 3 ? 1.0 : 0.0, 1e-12) << "a lone particle is round";
}

// Only clusters of particles with velocities carry a dispersion: not a
// sample (--coarse sample, or a node whose capacity cannot give every octant
// and type a cluster), not a dataset without velocities.
TEST(AggregateParent, OnlyClustersOfParticlesWithVelocitiesCarryADispersion) {
  const ParticleChunk input = Clumpy(13, 6000);  // three types
  const auto carriers = [&](const ParticleChunk& particles, const SubtreeOptions& options) {
    std::size_t inner = 0, with = 0;
    std::map<NodeKey, NodePoints> nodes;
    BuildSubtree(particles, NodeKey::Root(), kCube, options, [&](NodeKey key, const NodePoints& p) { nodes[key] = p; });
    for (const auto& [key, points] : nodes) {
      bool leaf = true;
      for (int o = 0; o < 8; ++o) leaf = leaf && !nodes.count(key.Child(o));
      if (leaf) continue;
      ++inner;
      with += points.velocity_dispersion.empty() ? 0 : 1;
    }
    EXPECT_GT(inner, 0u);
    return std::pair{inner, with};
  };
  SubtreeOptions clusters;
  clusters.capacity = 100;
  const auto [inner, with] = carriers(input, clusters);
  EXPECT_EQ(with, inner);
  SubtreeOptions sample = clusters;
  sample.coarse = CoarsePoints::kSample;
  EXPECT_EQ(carriers(input, sample).second, 0u);
  SubtreeOptions too_small = clusters;
  too_small.capacity = 15;  // two types need 16, three 24
  EXPECT_EQ(carriers(input, too_small).second, 0u);
  ParticleChunk still = input;
  still.velocity.clear();
  EXPECT_EQ(carriers(still, clusters).second, 0u);
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
  std::size_t with_dispersion = 0;
  for (const auto& [key, points] : whole) {
    ASSERT_TRUE(pieces.count(key)) << key.Path();
    EXPECT_EQ(EncodeBlock(pieces.at(key), key, kCube), EncodeBlock(points, key, kCube)) << key.Path();
    EXPECT_EQ(pieces.at(key).velocity_dispersion, points.velocity_dispersion) << key.Path();
    with_dispersion += points.velocity_dispersion.empty() ? 0 : 1;
  }
  EXPECT_GT(with_dispersion, 5u) << "the inner nodes' clusters carry their velocity dispersion";
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
