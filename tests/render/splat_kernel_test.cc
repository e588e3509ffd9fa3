// The kernel of render/splat_kernel.h and the reference rasterizer that
// applies it: every blob's pixels sum to its weight.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "render/reference_rasterizer.h"
#include "render/splat_kernel.h"

namespace octocosm {
namespace {

TEST(SplatKernelTest, CubicKernelIsContinuousAndVanishesAtOne) {
  EXPECT_DOUBLE_EQ(CubicKernel(0), 1);
  EXPECT_NEAR(CubicKernel(0.5 - 1e-12), CubicKernel(0.5), 1e-10);
  EXPECT_DOUBLE_EQ(CubicKernel(0.5), 0.25);
  EXPECT_DOUBLE_EQ(CubicKernel(1), 0);
  EXPECT_DOUBLE_EQ(CubicKernel(1.5), 0);
  for (double q = 0; q < 1; q += 0.01) EXPECT_GE(CubicKernel(q), CubicKernel(q + 0.01));
}

TEST(SplatKernelTest, IntegralConstantIsSevenPiOverForty) {
  // Midpoint rule over the unit disc in polar coordinates.
  double integral = 0;
  const int steps = 200000;
  for (int k = 0; k < steps; ++k) {
    const double q = (k + 0.5) / steps;
    integral += CubicKernel(q) * 2 * M_PI * q / steps;
  }
  EXPECT_NEAR(integral, kKernelIntegral, 1e-9);
}

// The documented bound: from R = 4 px on, the integral is within 4.1e-4 of
// the pixel sum wherever the centre falls.
TEST(SplatKernelTest, AnalyticNormalizationIsWithinItsBoundFromFourPixels) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  double worst = 0;
  for (double r = kExactNormalizationRadius; r < 40; r *= 1.13) {
    for (int k = 0; k < 40; ++k) {
      const double cx = u(rng) + 17, cy = u(rng) - 3;
      worst = std::max(worst, std::fabs(KernelNormalization(cx, cy, r) / KernelPixelSum(cx, cy, r) - 1));
    }
  }
  EXPECT_LT(worst, 4.1e-4);
  EXPECT_GT(worst, 0);  // it is an approximation: the test looks at the right branch
}

TEST(SplatKernelTest, SmallBlobsAreNormalizedExactly) {
  EXPECT_DOUBLE_EQ(KernelNormalization(0.3, 0.8, 1.0), KernelPixelSum(0.3, 0.8, 1.0));
  // At R = 1 every centre is within sqrt(2)/2 of a pixel centre: N > 0.
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-5, 5);
  for (int k = 0; k < 1000; ++k) EXPECT_GT(KernelPixelSum(u(rng), u(rng), kMinBlobRadius), 0.05);
}

TEST(SplatKernelTest, BlobRadiusIsClampedToOnePixelAndTheLargest) {
  EXPECT_DOUBLE_EQ(BlobRadius(1e-9, 1000, 1, 127), 1);
  EXPECT_DOUBLE_EQ(BlobRadius(0.01, 1000, 1, 127), 10);
  EXPECT_DOUBLE_EQ(BlobRadius(10, 1000, 1, 127), 127);
  EXPECT_GT(SpriteSize(3.2), 2 * 3.2);
  EXPECT_LE(SpriteSize(kDefaultMaxBlobRadius), 255);  // llvmpipe's largest point
  EXPECT_GE(GuardMargin(127), 127);
}

// Every blob inside the image adds exactly its weight (to 4.1e-4 above 4 px,
// to rounding below), and its colour channels carry weight * attribute.
TEST(ReferenceRasterizerTest, BlobsInsideTheImageConserveTheirWeight) {
  Camera camera;
  camera.position = {0, 0, 10};
  camera.look_at = {0, 0, 0};
  camera.near = 0.1;
  camera.far = 100;
  const RenderView view(camera, 200, 150);
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  for (double h : {0.001, 0.02, 0.05, 0.3, 1.0}) {
    ReferenceRasterizer r(view);
    double weight = 0, weighted_attribute = 0;
    for (int k = 0; k < 50; ++k) {
      const double p[3] = {u(rng) * 2, u(rng) * 1.5, u(rng)};
      const double w = 0.5 + u(rng) * 0.25, a = u(rng);
      ASSERT_TRUE(r.Add(p, w, h, a, k % 2 == 0));
      weight += w;
      weighted_attribute += w * a;
    }
    double sum[4] = {0, 0, 0, 0};
    for (std::size_t i = 0; i < r.image().rgba.size(); ++i) sum[i % 4] += r.image().rgba[i];
    SCOPED_TRACE("h = " + std::to_string(h));
    EXPECT_NEAR(sum[0] / weight, 1, 4.1e-4);
    EXPECT_NEAR(sum[1], weighted_attribute, 4.1e-4 * weight);
    EXPECT_GT(sum[3], 0.2 * weight);
  }
}

TEST(ReferenceRasterizerTest, PointsOutsideTheDepthRangeAreNotDrawn) {
  Camera camera;
  camera.position = {0, 0, 10};
  camera.look_at = {0, 0, 0};
  camera.near = 1;
  camera.far = 20;
  const RenderView view(camera, 64, 64);
  ReferenceRasterizer r(view);
  const double behind[3] = {0, 0, 11}, too_far[3] = {0, 0, -11}, inside[3] = {0, 0, 0};
  EXPECT_FALSE(r.Add(behind, 1, 0.1, 0, false));
  EXPECT_FALSE(r.Add(too_far, 1, 0.1, 0, false));
  EXPECT_TRUE(r.Add(inside, 1, 0.1, 0, false));
  EXPECT_EQ(r.points_drawn(), 1u);
}

// A blob straddling the image's edge adds exactly the share of its pixels
// that lie inside.
TEST(ReferenceRasterizerTest, BlobsOnTheEdgeAddOnlyWhatReachesIn) {
  Camera camera;
  camera.position = {0, 0, 10};
  camera.look_at = {0, 0, 0};
  camera.near = 0.1;
  camera.far = 100;
  const RenderView view(camera, 100, 100);
  ReferenceRasterizer r(view);
  ProjectedPoint c;
  const double p[3] = {-6.0, 0.1, 0};  // projects left of the image
  ASSERT_TRUE(view.Project(p, c));
  const double h = 0.5;
  const double radius = BlobRadius(h, view.focal_pixels(), c.depth, view.max_blob_radius());
  ASSERT_LT(c.x, 0);
  ASSERT_GT(c.x + radius, 1);
  r.Add(p, 1, h, 0, false);
  double inside = 0;
  for (int j = 0; j < 100; ++j) {
    for (int i = 0; i < 100; ++i) {
      const double d = std::hypot(i + 0.5 - c.x, j + 0.5 - c.y) / radius;
      inside += CubicKernel(d);
    }
  }
  double sum = 0;
  for (std::size_t i = 0; i < r.image().rgba.size(); i += 4) sum += r.image().rgba[i];
  EXPECT_NEAR(sum, inside / KernelNormalization(c.x, c.y, radius), 1e-12);
  EXPECT_GT(sum, 0);
  EXPECT_LT(sum, 0.5);
}

}  // namespace
}  // namespace octocosm
