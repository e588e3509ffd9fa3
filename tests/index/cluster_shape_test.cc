#include "index/cluster_shape.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace octocosm {
namespace {

// A round covariance of any size is the identity, stored exactly.
TEST(ClusterShape, RoundIsTheIdentityExactly) {
  for (const double variance : {1e-12, 1.0, 3e7}) {
    const auto code = EncodeShape({variance, variance, variance, 0, 0, 0});
    EXPECT_EQ(code, kRoundShapeCode);
    const SymmetricMatrix s = DecodeShape(code);
    for (int k = 0; k < 6; ++k) EXPECT_EQ(s[k], k < 3 ? 1.0 : 0.0);
  }
}

// A shape keeps trace 3, is pulled towards the sphere by kShapeFloor, and
// rounds to within half a code step.
TEST(ClusterShape, StretchedCovarianceRoundTripsWithinHalfAStep) {
  const SymmetricMatrix c = {9.0, 1.0, 0.5, 2.0, -0.7, 0.1};  // positive definite
  const double mean = (c[0] + c[1] + c[2]) / 3;
  const SymmetricMatrix s = DecodeShape(EncodeShape(c));
  for (int k = 0; k < 6; ++k) {
    const double want = (1 - kShapeFloor) * c[k] / mean + kShapeFloor * (k < 3 ? 1 : 0);
    EXPECT_NEAR(s[k], want, k < 3 ? 0.5 / 85 : 1.5 / 254) << k;
  }
  EXPECT_NEAR(s[0] + s[1] + s[2], 3, 1.5 / 85);
}

// A line (one axis only) is held to the floor: its thinnest axes keep
// kShapeFloor of the mean variance.
TEST(ClusterShape, ALineIsHeldToTheFloor) {
  const SymmetricMatrix s = DecodeShape(EncodeShape({1, 0, 0, 0, 0, 0}));
  EXPECT_NEAR(s[0], 3 * (1 - kShapeFloor) + kShapeFloor, 0.5 / 85);
  EXPECT_NEAR(s[1], kShapeFloor, 0.5 / 85);
  EXPECT_NEAR(s[2], kShapeFloor, 0.5 / 85);
}

// Covariances without a positive finite trace give the round shape; codes
// stay in range for extreme off-diagonal entries.
TEST(ClusterShape, DegenerateInputGivesRoundOrClampedCodes) {
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(EncodeShape({0, 0, 0, 0, 0, 0}), kRoundShapeCode);
  EXPECT_EQ(EncodeShape({nan, 1, 1, 0, 0, 0}), kRoundShapeCode);
  EXPECT_EQ(EncodeShape({inf, 1, 1, 0, 0, 0}), kRoundShapeCode);
  EXPECT_EQ(EncodeShape({-1, -1, -1, 0, 0, 0}), kRoundShapeCode);
  const auto code = EncodeShape({1, 1, 1, 50, -50, 0});  // not a covariance, but must not overflow
  EXPECT_EQ(code[3], 254);
  EXPECT_EQ(code[4], 0);
  EXPECT_EQ(code[5], 127);
}

}  // namespace
}  // namespace octocosm
