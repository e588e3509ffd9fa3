// NthLargest against a full sort: random values, ranks from the largest to
// the smallest, ties, and a sample that holds the largest values, which
// leaves too few values above its bound.
#include "index/nth_largest.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <random>
#include <vector>

namespace octocosm {
namespace {

double BySorting(std::vector<double> values, std::size_t rank) {
  std::sort(values.begin(), values.end(), std::greater<>());
  return values[rank];
}

TEST(NthLargest, MatchesASortAtEveryKindOfRank) {
  std::mt19937_64 random(11);
  std::lognormal_distribution<double> priority(0, 2);
  for (const std::size_t m : {1u, 10u, 5000u, 8192u, 50000u, 131072u}) {
    std::vector<double> values(m);
    for (double& v : values) v = priority(random);
    for (const std::size_t rank : {std::size_t{0}, m / 8, m / 4 - (m >= 4 ? 1 : 0), m / 2, m - 1}) {
      EXPECT_EQ(NthLargest(values, rank), BySorting(values, rank)) << m << " values, rank " << rank;
    }
  }
}

TEST(NthLargest, TiesAreCountedOneByOne) {
  std::vector<double> values(20000, 1.0);
  for (std::size_t i = 0; i < 3000; ++i) values[6 * i] = 2.0;
  EXPECT_EQ(NthLargest(values, 2999), 2.0);
  EXPECT_EQ(NthLargest(values, 3000), 1.0);
}

TEST(NthLargest, ASampleHoldingTheLargestValuesFallsBackToAllOfThem) {
  // The sample reads every 16th value; those are the 1024 largest.
  std::mt19937_64 random(12);
  std::uniform_real_distribution<double> small(0, 1);
  std::vector<double> values(16384);
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = i % 16 == 0 ? 1000.0 + static_cast<double>(i) : small(random);
  for (const std::size_t rank : {100u, 1023u, 1024u, 2000u, 4000u}) {
    EXPECT_EQ(NthLargest(values, rank), BySorting(values, rank)) << "rank " << rank;
  }
  // And from the other end: ranks past the middle count from the smallest.
  for (double& v : values) v = -v;
  for (const std::size_t rank : {16283u, 15360u, 15359u, 14383u, 12383u}) {
    EXPECT_EQ(NthLargest(values, rank), BySorting(values, rank)) << "rank " << rank;
  }
}

}  // namespace
}  // namespace octocosm
