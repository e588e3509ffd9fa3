// The Hermite velocity scale of an epoch pair (VelocityScaleFit): exact on
// trapezoid-rule motion, unit-free, robust to particles the rule fails for,
// and guarded where nothing can be fitted.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "ingest/epoch_join.h"

namespace octocosm {
namespace {

struct Pair {
  double d[3];
  float v[3], next_v[3];
};

// Particles that move by exactly `step` * (v + next_v) / 2, with the
// velocities then reported in units `velocity_unit` times smaller.
std::vector<Pair> Trapezoid(std::size_t n, double step, double velocity_unit, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> v(0, 100), kick(0, 10);
  std::vector<Pair> pairs(n);
  for (Pair& p : pairs) {
    for (int a = 0; a < 3; ++a) {
      // Rounded to float first, so that d is exactly step * vbar of the stored values.
      const double v0 = static_cast<float>(v(rng)), v1 = static_cast<float>(v0 + kick(rng));
      p.d[a] = step * 0.5 * (v0 + v1);
      p.v[a] = static_cast<float>(v0 * velocity_unit);
      p.next_v[a] = static_cast<float>(v1 * velocity_unit);
    }
  }
  return pairs;
}

VelocityScaleFit Fit(const std::vector<Pair>& pairs) {
  VelocityScaleFit fit;
  for (const Pair& p : pairs) fit.Add(p.d, p.v, p.next_v);
  return fit;
}

TEST(VelocityScaleFit, RecoversTheStepOfTrapezoidMotionInAnyUnits) {
  for (const double unit : {1.0, 1000.0, 1e-3}) {
    const VelocityScaleFit fit = Fit(Trapezoid(5000, 0.5, unit, 1));
    // Exact for unit 1; otherwise the velocities' float rounding (2^-24) limits it.
    EXPECT_NEAR(fit.velocity_scale(), 0.5 / unit, 1e-7 / unit) << unit;
    EXPECT_NEAR(fit.least_squares_scale(), 0.5 / unit, 1e-7 / unit) << unit;
    EXPECT_LT(fit.fit_residual(), 1e-7) << unit;
    EXPECT_NEAR(fit.inlier_fraction(), 1.0, 1e-12) << unit;
  }
}

TEST(VelocityScaleFit, ASeriesInReverseTimeHasANegativeScale) {
  std::vector<Pair> pairs = Trapezoid(2000, 0.5, 1, 2);
  for (Pair& p : pairs) {
    for (double& d : p.d) d = -d;
  }
  EXPECT_NEAR(Fit(pairs).velocity_scale(), -0.5, 1e-12);
}

// Particles that went round an orbit between the snapshots move against
// their velocities or hardly at all: the plain least-squares scale follows
// them, the fitted scale does not.
TEST(VelocityScaleFit, ParticlesTheTrapezoidRuleFailsForDoNotMoveTheScale) {
  std::vector<Pair> pairs = Trapezoid(7000, 0.5, 1, 3);
  std::mt19937_64 rng(4);
  std::normal_distribution<double> anywhere(0, 50);
  for (std::size_t i = 0; i < pairs.size(); i += 3) {  // a third of them
    for (double& d : pairs[i].d) d = anywhere(rng);
  }
  const VelocityScaleFit fit = Fit(pairs);
  EXPECT_NEAR(fit.velocity_scale(), 0.5, 0.01);
  EXPECT_LT(fit.least_squares_scale(), 0.4);
  EXPECT_GT(fit.inlier_fraction(), 0.6);
  EXPECT_LT(fit.inlier_fraction(), 0.75);
  // The residual is over every particle, the stray third included.
  EXPECT_GT(fit.fit_residual(), 0.3);
  EXPECT_LT(fit.fit_residual(), 1.0);
}

TEST(VelocityScaleFit, NothingToFitGivesScaleZeroAndResidualOne) {
  const VelocityScaleFit empty;
  EXPECT_EQ(empty.velocity_scale(), 0.0);
  EXPECT_EQ(empty.least_squares_scale(), 0.0);
  EXPECT_EQ(empty.fit_residual(), 1.0);

  std::vector<Pair> still = Trapezoid(100, 0.5, 1, 5);
  for (Pair& p : still) {
    for (int a = 0; a < 3; ++a) p.v[a] = p.next_v[a] = 0;  // displacements, but no velocities
  }
  EXPECT_EQ(Fit(still).velocity_scale(), 0.0);
  EXPECT_EQ(Fit(still).fit_residual(), 1.0);

  std::vector<Pair> frozen = Trapezoid(100, 0.5, 1, 6);
  for (Pair& p : frozen) {
    for (double& d : p.d) d = 0;  // velocities, but nothing moved
  }
  EXPECT_EQ(Fit(frozen).velocity_scale(), 0.0);
  EXPECT_EQ(Fit(frozen).least_squares_scale(), 0.0);
  EXPECT_EQ(Fit(frozen).fit_residual(), 1.0);
}

}  // namespace
}  // namespace octocosm
