// ExtendedSum: exact where a double sum is not, and the same for the same
// values in the same order.
#include "index/extended_sum.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

namespace octocosm {
namespace {

TEST(ExtendedSum, KeepsWhatADoubleSumLoses) {
  const double big = std::ldexp(1.0, 60);
  // Every value lands in some running sum: the large pair cancels within the
  // first, and the small values in each of the four and past them are kept.
  const std::vector<double> values = {big, 1, 1, 1, -big, 1, 1, 1, 1};
  double naive = 0;
  for (const double v : values) naive += v;
  EXPECT_NE(naive, 7.0);
  EXPECT_EQ(ExtendedSum(values), 7.0L);
  EXPECT_EQ(ExtendedSum(std::vector<double>{}), 0.0L);
  EXPECT_EQ(ExtendedSum(std::vector<double>{2.5}), 2.5L);
  EXPECT_EQ(ExtendedSum(std::vector<double>{1, 2, 3}), 6.0L);
}

TEST(ExtendedSum, IsExactForIntegersOfEveryLength) {
  // Integers below 2^53 whose total stays below 2^64: every partial sum is
  // exact in 80-bit precision, so the result must be the exact total.
  std::mt19937_64 random(7);
  for (std::size_t n = 0; n < 40; ++n) {
    std::vector<double> values(n);
    std::uint64_t exact = 0;
    for (double& v : values) {
      const std::uint64_t k = random() >> 12;  // below 2^52
      v = static_cast<double>(k);
      exact += k;
    }
    EXPECT_EQ(ExtendedSum(values), static_cast<long double>(exact)) << n;
  }
}

}  // namespace
}  // namespace octocosm
