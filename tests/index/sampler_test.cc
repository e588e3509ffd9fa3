// Density-weighted priority sampling: determinism, exact totals,
// unbiasedness (checked statistically over many seeds) and the effect of the
// density exponent.
#include "index/sampler.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <random>

#include "base/error.h"

namespace octocosm {
namespace {

const Cube kCube{{0, 0, 0}, 1, false};

struct Population {
  std::vector<double> position;
  std::vector<double> weight;
  std::vector<std::uint64_t> id;
  std::size_t size() const { return weight.size(); }
};

// A dense Gaussian clump around (0.7, 0.7, 0.7) on a sparse uniform background.
Population Clustered(std::mt19937_64& rng, std::size_t clump, std::size_t background) {
  Population p;
  std::normal_distribution<double> g(0.7, 0.03);
  std::uniform_real_distribution<double> u(0, 1);
  std::lognormal_distribution<double> mass(0, 0.5);
  for (std::size_t i = 0; i < clump + background; ++i) {
    for (int a = 0; a < 3; ++a) p.position.push_back(std::clamp(i < clump ? g(rng) : u(rng), 0.0, 0.999999));
    p.weight.push_back(mass(rng));
    p.id.push_back(1000 + 7 * i);
  }
  return p;
}

Sample SampleAll(const Population& p, std::size_t n, const SamplerOptions& options) {
  return SampleNode(p.position, p.weight, p.id, NodeKey::Root(), kCube, n, options);
}

double Total(const std::vector<double>& w) {
  long double s = 0;
  for (double x : w) s += x;
  return static_cast<double>(s);
}

TEST(Sampler, KeepsEverythingWhenThePopulationFits) {
  std::mt19937_64 rng(1);
  const Population p = Clustered(rng, 50, 50);
  const Sample s = SampleAll(p, 100, {});
  ASSERT_EQ(s.kept.size(), 100u);
  EXPECT_EQ(s.weight, p.weight);
  EXPECT_EQ(s.threshold, 0);
  for (double h : s.smoothing) {
    EXPECT_GE(h, 1.0 / 65536);
    EXPECT_LE(h, 1.0);
  }
}

TEST(Sampler, KeepsNPointsWhoseWeightsSumToTheMass) {
  std::mt19937_64 rng(2);
  const Population p = Clustered(rng, 6000, 4000);
  for (double alpha : {0.0, 0.5, 1.0}) {
    SamplerOptions options;
    options.alpha = alpha;
    const Sample s = SampleAll(p, 700, options);
    ASSERT_EQ(s.kept.size(), 700u);
    EXPECT_TRUE(std::is_sorted(s.kept.begin(), s.kept.end()));
    EXPECT_EQ(std::adjacent_find(s.kept.begin(), s.kept.end()), s.kept.end());
    EXPECT_NEAR(Total(s.weight) / Total(p.weight), 1.0, 1e-12) << alpha;
    EXPECT_GT(s.threshold, 0);
    for (std::size_t j = 0; j < s.kept.size(); ++j) {
      EXPECT_GT(s.weight[j], 0);
      EXPECT_GE(s.smoothing[j], 1.0 / 65536);
      EXPECT_LE(s.smoothing[j], 1.0);
    }
  }
}

TEST(Sampler, IsDeterministicAndIndependentOfInputOrder) {
  std::mt19937_64 rng(3);
  const Population p = Clustered(rng, 3000, 2000);
  SamplerOptions options;
  options.seed = 99;
  const Sample a = SampleAll(p, 400, options);
  const Sample b = SampleAll(p, 400, options);
  EXPECT_EQ(a.kept, b.kept);
  EXPECT_EQ(a.weight, b.weight);

  std::vector<std::size_t> perm(p.size());
  std::iota(perm.begin(), perm.end(), 0);
  std::shuffle(perm.begin(), perm.end(), rng);
  Population q;
  for (std::size_t i : perm) {
    q.position.insert(q.position.end(), &p.position[3 * i], &p.position[3 * i] + 3);
    q.weight.push_back(p.weight[i]);
    q.id.push_back(p.id[i]);
  }
  const Sample c = SampleAll(q, 400, options);
  std::map<std::uint64_t, std::pair<double, double>> by_id_a, by_id_c;
  for (std::size_t j = 0; j < a.kept.size(); ++j) by_id_a[p.id[a.kept[j]]] = {a.weight[j], a.smoothing[j]};
  for (std::size_t j = 0; j < c.kept.size(); ++j) by_id_c[q.id[c.kept[j]]] = {c.weight[j], c.smoothing[j]};
  ASSERT_EQ(by_id_a.size(), by_id_c.size());
  for (const auto& [id, ws] : by_id_a) {
    ASSERT_TRUE(by_id_c.count(id)) << id;
    EXPECT_NEAR(by_id_c[id].first / ws.first, 1.0, 1e-12);
    EXPECT_NEAR(by_id_c[id].second / ws.second, 1.0, 1e-12);
  }

  options.seed = 100;
  const Sample d = SampleAll(p, 400, options);
  EXPECT_NE(a.kept, d.kept);
}

// Points with the same ID, weight and density cell draw the same priority:
// the threshold ties with those kept, and the lower ID, then the lower
// index, decides, so exactly n points are kept.
TEST(Sampler, TiedPrioritiesAreSettledByIdThenIndex) {
  Population p;
  for (std::size_t i = 0; i < 40; ++i) {
    const double at[3] = {0.5, 0.5, 0.5};
    p.position.insert(p.position.end(), at, at + 3);
    p.weight.push_back(1.0);
    p.id.push_back(i < 10 ? 7 : 5);
  }
  // ID 5 draws the smaller u at the root, so the higher priority: its 30
  // points tie at the threshold and the 25 with the lowest indices stay.
  ASSERT_LT(PriorityUniform(5, LevelSeed(0, 0)), PriorityUniform(7, LevelSeed(0, 0)));
  const Sample s = SampleAll(p, 25, {});
  std::vector<std::uint32_t> expected(25);
  std::iota(expected.begin(), expected.end(), 10u);
  EXPECT_EQ(s.kept, expected);
  EXPECT_NEAR(Total(s.weight), 40.0, 1e-12);
}

// The mean over many seeds of the estimated mass in a region is the region's
// true mass: priority sampling's estimator is unbiased.
TEST(Sampler, EstimatesRegionMassesWithoutBias) {
  std::mt19937_64 rng(4);
  const Population p = Clustered(rng, 3000, 3000);
  struct Region {
    const char* name;
    double lo[3], hi[3];
  };
  const Region regions[] = {
      {"sparse corner", {0, 0, 0}, {0.4, 0.4, 0.4}},
      {"clump edge", {0.7, 0.6, 0.6}, {0.75, 0.8, 0.8}},
      {"slab", {0.2, 0, 0}, {0.3, 1, 1}},
  };
  for (double alpha : {0.0, 0.5, 1.0}) {
    for (const Region& r : regions) {
      auto inside = [&](std::size_t i) {
        for (int a = 0; a < 3; ++a) {
          if (p.position[3 * i + a] < r.lo[a] || p.position[3 * i + a] >= r.hi[a]) return false;
        }
        return true;
      };
      double truth = 0;
      for (std::size_t i = 0; i < p.size(); ++i) truth += inside(i) ? p.weight[i] : 0;
      const int seeds = 200;
      double sum[2] = {0, 0}, sum2[2] = {0, 0};  // raw estimates, rescaled weights
      for (int seed = 0; seed < seeds; ++seed) {
        SamplerOptions options;
        options.alpha = alpha;
        options.seed = static_cast<std::uint64_t>(seed);
        const Sample s = SampleAll(p, 300, options);
        double estimate[2] = {0, 0};
        for (std::size_t j = 0; j < s.kept.size(); ++j) {
          if (!inside(s.kept[j])) continue;
          estimate[0] += s.estimate[j];
          estimate[1] += s.weight[j];
        }
        for (int k = 0; k < 2; ++k) sum[k] += estimate[k], sum2[k] += estimate[k] * estimate[k];
      }
      // The rescaled weights carry the ratio estimator's O(1/n) bias, which
      // at alpha = 1 and this contrast exceeds the noise of 200 runs (see
      // sampler.h); the raw estimates must be unbiased at every alpha.
      for (int k = 0; k < (alpha <= 0.5 ? 2 : 1); ++k) {
        const double mean = sum[k] / seeds;
        const double sd_of_mean = std::sqrt((sum2[k] / seeds - mean * mean) / (seeds - 1));
        EXPECT_GT(sd_of_mean, 0) << r.name;
        EXPECT_LT(std::fabs(mean - truth), 4 * sd_of_mean + 1e-9 * truth)
            << r.name << " alpha " << alpha << (k ? " rescaled" : " raw") << ": mean " << mean << " truth "
            << truth << " sd " << sd_of_mean;
      }
    }
  }
}

TEST(Sampler, DensityWeightingKeepsMoreOfTheSparseRegions) {
  std::mt19937_64 rng(5);
  const Population p = Clustered(rng, 9000, 1000);
  auto kept_in_background = [&](double alpha) {
    SamplerOptions options;
    options.alpha = alpha;
    const Sample s = SampleAll(p, 500, options);
    // The clump's points are the first 9000.
    return std::count_if(s.kept.begin(), s.kept.end(), [](std::uint32_t i) { return i >= 9000; });
  };
  const auto mass_proportional = kept_in_background(0.0);
  const auto half = kept_in_background(0.5);
  const auto full = kept_in_background(1.0);
  EXPECT_GT(mass_proportional, 20);  // ~ 10% of the mass
  EXPECT_LT(mass_proportional, 90);
  EXPECT_GT(half, 1.5 * static_cast<double>(mass_proportional));
  EXPECT_GT(full, half);
}

TEST(Sampler, SmoothingLengthFollowsTheVolumePerPoint) {
  // A uniform population: each kept point stands for volume 1/n.
  std::mt19937_64 rng(6);
  Population p;
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 64000; ++i) {
    for (int a = 0; a < 3; ++a) p.position.push_back(u(rng));
    p.weight.push_back(1);
    p.id.push_back(static_cast<std::uint64_t>(i));
  }
  SamplerOptions options;
  options.density_grid_bits = 3;  // ~125 points per cell: a smooth density estimate
  const Sample s = SampleAll(p, 1000, options);
  std::vector<double> h = s.smoothing;
  std::nth_element(h.begin(), h.begin() + 500, h.end());
  EXPECT_NEAR(h[500], kSmoothingEta * std::cbrt(1.0 / 1000), 0.15 * h[500]);
  std::vector<double> lh = LeafSmoothingLengths(p.position, p.weight, NodeKey::Root(), kCube, options);
  std::nth_element(lh.begin(), lh.begin() + 32000, lh.end());
  EXPECT_NEAR(lh[32000], kSmoothingEta * std::cbrt(1.0 / 64000), 0.15 * lh[32000]);
}

TEST(Sampler, EachLengthComesFromItsOwnWeightAndCell) {
  // Step 5 point by point: h = SmoothingLengthFor(W, the weight of the
  // point's fine cell, ...). Equal and unequal weights, cells of one point
  // and of many, so that points share a weight but not a cell weight, and a
  // cell but not a weight.
  std::mt19937_64 rng(12);
  for (const bool equal_masses : {true, false}) {
    SCOPED_TRACE(equal_masses ? "equal masses" : "lognormal masses");
    Population p = Clustered(rng, 3000, 3000);
    if (equal_masses) std::fill(p.weight.begin(), p.weight.end(), 2.5);
    const SamplerOptions options;
    const NodeKey root = NodeKey::Root();
    std::map<std::uint32_t, double> cell_weight;  // summed in point order, as the sampler does
    std::vector<std::uint32_t> cell(p.size());
    for (std::size_t i = 0; i < p.size(); ++i) {
      cell[i] = DensityCellIndex(&p.position[3 * i], root, kCube, options.density_grid_bits);
      cell_weight[cell[i]] += p.weight[i];
    }
    const double edge = kCube.NodeSize(options.density_grid_bits);
    const auto expected = [&](std::size_t i, double weight) {
      return SmoothingLengthFor(weight, cell_weight[cell[i]], edge, kCube.NodeSize(0));
    };
    const std::vector<double> leaf = LeafSmoothingLengths(p.position, p.weight, root, kCube, options);
    for (std::size_t i = 0; i < p.size(); ++i) ASSERT_EQ(leaf[i], expected(i, p.weight[i])) << "leaf point " << i;
    const Sample s = SampleAll(p, 1000, options);
    for (std::size_t j = 0; j < s.kept.size(); ++j) {
      ASSERT_EQ(s.smoothing[j], expected(s.kept[j], s.weight[j])) << "kept point " << j;
    }
  }
}

TEST(Sampler, UniformsAreInTheOpenClosedUnitInterval) {
  double sum = 0;
  for (std::uint64_t id = 0; id < 100000; ++id) {
    const double u = PriorityUniform(id, 5);
    ASSERT_GT(u, 0);
    ASSERT_LE(u, 1);
    sum += u;
  }
  EXPECT_NEAR(sum / 100000, 0.5, 0.005);
  EXPECT_NE(PriorityUniform(1, 5), PriorityUniform(1, 6));
  const double a[3] = {1, 2, 3}, b[3] = {1, 2, 3.0000000001};
  EXPECT_EQ(SamplingId(a), SamplingId(a));
  EXPECT_NE(SamplingId(a), SamplingId(b));
}

TEST(Sampler, RejectsBadInput) {
  std::mt19937_64 rng(7);
  Population p = Clustered(rng, 10, 10);
  auto expect_invalid = [&](const Population& q, std::size_t n, SamplerOptions options) {
    try {
      SampleAll(q, n, options);
      ADD_FAILURE();
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
    }
  };
  expect_invalid(p, 0, {});
  SamplerOptions bad;
  bad.alpha = -1;
  expect_invalid(p, 5, bad);
  bad = {};
  bad.density_grid_bits = 9;
  expect_invalid(p, 5, bad);
  Population q = p;
  q.weight[3] = 0;
  expect_invalid(q, 5, {});
  q = p;
  q.id.pop_back();
  expect_invalid(q, 5, {});
}

}  // namespace
}  // namespace octocosm
