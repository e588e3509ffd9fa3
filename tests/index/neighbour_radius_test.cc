#include "index/neighbour_radius.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "base/error.h"

namespace octocosm {
namespace {

// The k-th smallest distance from `q` to the points, by sorting all of them.
double BruteForceRadius(const std::vector<double>& points, const double* q, int k) {
  std::vector<double> d;
  for (std::size_t i = 0; i < points.size() / 3; ++i) {
    const double dx = points[3 * i] - q[0], dy = points[3 * i + 1] - q[1], dz = points[3 * i + 2] - q[2];
    d.push_back(std::sqrt(dx * dx + dy * dy + dz * dz));
  }
  if (d.size() < static_cast<std::size_t>(k)) return std::numeric_limits<double>::infinity();
  std::nth_element(d.begin(), d.begin() + (k - 1), d.end());
  return d[static_cast<std::size_t>(k - 1)];
}

// `n` points in the unit cube: every other one in a Gaussian clump (sigma
// 0.01) around (centre, centre, centre), the others uniform.
std::vector<double> ClumpAndBackground(int n, double centre, std::mt19937_64& rng) {
  std::normal_distribution<double> clump(0.0, 0.01);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::vector<double> points;
  for (int i = 0; i < n; ++i) {
    const bool in_clump = i % 2 == 0;
    for (int a = 0; a < 3; ++a) points.push_back(in_clump ? centre + clump(rng) : uniform(rng));
  }
  return points;
}

TEST(NeighbourRadii, EqualsTheKthDistanceOfAllPointsOnClusteredPoints) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const std::vector<double> points = ClumpAndBackground(3000, 0.3, rng);
  const NeighbourRadii radii(points);
  for (int k : {1, 2, 8, 32, 100}) {
    for (std::size_t i = 0; i < 3000; i += 37) {
      // Queries at particles (the particle counts itself) and between them.
      EXPECT_DOUBLE_EQ(radii.Radius(&points[3 * i], k), BruteForceRadius(points, &points[3 * i], k)) << k << " " << i;
      const double q[3] = {uniform(rng), uniform(rng), uniform(rng)};
      EXPECT_DOUBLE_EQ(radii.Radius(q, k), BruteForceRadius(points, q, k)) << k;
    }
  }
  // k = 1 at a particle is the particle itself.
  EXPECT_EQ(radii.Radius(&points[0], 1), 0.0);
}

// A set cut into blocks, each with its own tree, built on several threads:
// every radius equals the one tree's, whether the blocks are compact (slabs
// of points sorted along x) or overlap everywhere (points in random order).
TEST(NeighbourRadii, BlocksBuiltOnSeveralThreadsGiveTheOneTreesRadii) {
  std::mt19937_64 rng(11);
  std::normal_distribution<double> clump(0.0, 0.02);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const std::size_t n = 200000;
  std::vector<double> points;
  points.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const bool in_clump = i % 3 == 0;
    for (int a = 0; a < 3; ++a) points.push_back(in_clump ? 0.5 + clump(rng) : uniform(rng));
  }
  std::vector<double> sorted_by_x = points;  // slabs along x: compact blocks
  {
    std::vector<std::size_t> order(n);
    for (std::size_t i = 0; i < n; ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return points[3 * a] < points[3 * b]; });
    for (std::size_t i = 0; i < n; ++i) {
      for (int a = 0; a < 3; ++a) sorted_by_x[3 * i + a] = points[3 * order[i] + a];
    }
  }
  const NeighbourRadii one(points);
  EXPECT_EQ(one.blocks(), 1u);
  std::vector<std::size_t> begins;
  for (std::size_t b = 0; b < 9; ++b) begins.push_back(n * b * b / 81);  // uneven blocks
  for (const std::vector<double>* set : {&points, &sorted_by_x}) {
    const NeighbourRadii blocks(*set, begins, 4);
    EXPECT_EQ(blocks.blocks(), 9u);
    for (int k : {1, 32}) {
      for (std::size_t i = 0; i < n; i += 331) {
        EXPECT_EQ(blocks.Radius(&(*set)[3 * i], k), one.Radius(&(*set)[3 * i], k)) << k << " " << i;
      }
      const double far[3] = {3.0, -2.0, 0.5};
      EXPECT_EQ(blocks.Radius(far, k), one.Radius(far, k));
    }
  }
  // Blocks must start at 0, ascend and not be empty.
  const std::size_t bad[][2] = {{1, 5}, {0, 0}, {0, n}};
  for (const auto& b : bad) EXPECT_THROW(NeighbourRadii(points, std::span<const std::size_t>(b, 2), 2), Error);
}

// A bound from the previous query (its radius plus the step) gives every
// radius the search without one gives; so does a bound below the answer,
// which is searched again, and one at exactly the answer.
TEST(NeighbourRadii, ABoundNeverChangesTheAnswer) {
  std::mt19937_64 rng(13);
  const std::vector<double> points = ClumpAndBackground(8000, 0.4, rng);
  const std::vector<std::size_t> begins = {0, 2000, 5000};
  const NeighbourRadii radii(points, begins, 2);
  for (int k : {1, 8, 32}) {
    double previous = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < 8000; i += 7) {
      const double* q = &points[3 * i];
      const double exact = radii.Radius(q, k);
      ASSERT_EQ(exact, BruteForceRadius(points, q, k)) << k << " " << i;
      double step = 0;
      if (i >= 7) {
        for (int a = 0; a < 3; ++a) step += (q[a] - q[a - 21]) * (q[a] - q[a - 21]);
      }
      EXPECT_EQ(radii.Radius(q, k, 0, previous + std::sqrt(step)), exact) << k << " " << i;
      EXPECT_EQ(radii.Radius(q, k, 2, exact), exact) << k << " " << i;
      EXPECT_EQ(radii.Radius(q, k, 1, exact * 0.5), exact) << k << " " << i;
      EXPECT_EQ(radii.Radius(q, k, 0, 0.0), exact) << k << " " << i;
      previous = exact;
    }
  }
}

TEST(NeighbourRadii, CoincidentPointsAndTooFewPoints) {
  std::vector<double> points(3 * 50, 0.25);
  const NeighbourRadii radii(points);
  EXPECT_EQ(radii.Radius(&points[0], 32), 0.0);
  EXPECT_EQ(radii.Radius(&points[0], 50), 0.0);
  EXPECT_TRUE(std::isinf(radii.Radius(&points[0], 51)));
  const NeighbourRadii none(std::span<const double>{});
  const double q[3] = {0, 0, 0};
  EXPECT_TRUE(std::isinf(none.Radius(q, 1)));
  EXPECT_ANY_THROW(radii.Radius(q, 0));
}

}  // namespace
}  // namespace octocosm
