// The level of detail that refines cluster by cluster (query/cluster_frontier.h,
// render/cluster_links.h) on OSMesa (ctest label "gl"): a clustered snapshot
// is generated and ingested (its inner nodes' clusters linked to their
// children's points), and the GPU's cut is checked against the full-detail
// picture and against the rule evaluated on the CPU in double.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "index/block_codec.h"
#include "index/node_hierarchy.h"
#include "render/offscreen_renderer.h"
#include "tests/support/hdr_compare.h"
#include "tests/support/render_scene.h"

namespace octocosm {
namespace {

using testing_support::RenderScene;

RenderScene* scene = nullptr;

class GlClusterCutTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { scene = testing_support::MakeRenderScene("gl-cluster-cut-test", 150000, 1, 5, 2000); }
  static void TearDownTestSuite() {
    delete scene;
    scene = nullptr;
  }

  static RenderView Overview(const Dataset& d) { return testing_support::OverviewOf(d); }
  static RenderView Inside(const Dataset& d) { return testing_support::InsideOf(d); }
  static SceneOptions Cut(double cluster_error) {
    SceneOptions o;
    o.cluster_error = cluster_error;
    o.splat_path = SplatPath::kRaster;
    return o;
  }
  static SceneOptions Full() {
    SceneOptions o;
    o.lod.pixel_threshold = 1e-9;
    o.splat_path = SplatPath::kRaster;
    return o;
  }
  static double MeanMass(const Dataset& d) { return d.summary(0).mass.value() / static_cast<double>(d.points(0)); }
};

double Total(const HdrImage& image) {
  double sum = 0;
  for (std::size_t i = 0; i < image.rgba.size(); i += 4) sum += image.rgba[i];
  return sum;
}

// The rule of docs/FORMAT.md section 4 on the CPU, in double, over every
// node of the store: how many points the cut of threshold tau takes.
std::uint64_t CutOnTheCpu(const Dataset& d, const RenderView& view, double tau) {
  const NodeHierarchy h = NodeHierarchy::Load(d, 0);
  const double q = std::pow(0.5 / view.focal_pixels(), 2);
  std::vector<std::vector<double>> errors(h.nodes().size());
  std::vector<std::vector<std::uint32_t>> links(h.nodes().size());
  std::uint64_t taken = 0;
  for (std::size_t n = 0; n < h.nodes().size(); ++n) {
    const NodeHierarchy::Node& node = h.nodes()[n];
    const NodeKey key = node.key;
    const Bytes bytes = d.store().ReadBlock({0, key.value()});
    const DecodedBlock block =
        DecodeBlock(bytes, ColumnBit(ColumnId::kPosition) | kClusterLinkColumns, key, d.cube(0), d.Where(0, key));
    const NodePoints& p = block.points;
    const std::size_t count = block.header.point_count;
    std::vector<double>& error = errors[n];
    error.assign(count, 0.0);
    for (std::size_t i = 0; i < count && !p.refine_bound.empty(); ++i) {
      double distance2 = 0;
      for (int a = 0; a < 3; ++a) {
        const double dx = p.position[3 * i + a] - view.camera().position[static_cast<std::size_t>(a)];
        distance2 += dx * dx;
      }
      const double gap = std::max(0.0, std::sqrt(distance2) - p.refine_bound[3 * i]);
      const double a = p.refine_bound[3 * i + 1], r = p.refine_bound[3 * i + 2];
      const double spread = a / (q * gap * gap);
      error[i] = !(a > 0 && r > 0) ? 0 : gap > 0 ? spread / std::sqrt(1 + spread / r) : INFINITY;
    }
    links[n] = p.child_cluster;
    // The parent's error of each point: its cluster's, by the parent's links.
    std::vector<double> parent_error(count, INFINITY);
    if (node.parent >= 0) {
      std::uint64_t first = 0;
      for (std::int32_t sibling : h.node(node.parent).children) {
        if (sibling == static_cast<std::int32_t>(n)) break;
        if (sibling >= 0) first += h.node(sibling).entry.point_count;
      }
      const auto& up = links[static_cast<std::size_t>(node.parent)];
      for (std::size_t i = 0; i < count; ++i) parent_error[i] = errors[static_cast<std::size_t>(node.parent)][up[first + i]];
    }
    for (std::size_t i = 0; i < count; ++i) taken += error[i] <= tau && parent_error[i] > tau;
  }
  return taken;
}

// Seen from outside with the whole box in view, every node is reached where
// the cut needs it, so the GPU's cut is the rule's: as many points as the CPU
// finds in double (a point whose error lies within float rounding of tau may
// fall either way: 1e-4 of them allowed), the whole mass (to the blob
// normalization's 1e-3, as any level of detail), fewer points the higher the
// threshold, and at threshold ~0 every particle, the full-detail picture.
TEST_F(GlClusterCutTest, TheCutDrawsEachParticleOnce) {
  const Dataset d = Dataset::Open(scene->store);
  ASSERT_EQ(d.cluster_columns() & kClusterLinkColumns, kClusterLinkColumns) << "the store links its clusters";
  const RenderView view = Overview(d);
  OffscreenRenderer full(d, HeadlessBackend::kOsMesa, Full());
  const Picture reference = full.Render(view, 0, {}, true);
  ASSERT_EQ(reference.stats.points_drawn, scene->particles);
  std::uint64_t previous = scene->particles + 1;
  for (const double cluster_error : {1e-300, 0.3, 3.0, 30.0, 300.0, 3000.0}) {
    SCOPED_TRACE("cluster error " + std::to_string(cluster_error));
    OffscreenRenderer cut(d, HeadlessBackend::kOsMesa, Cut(cluster_error));
    const Picture p = cut.Render(view, 0, {}, true);
    EXPECT_TRUE(p.stats.cluster_cut);
    const std::uint64_t cpu = CutOnTheCpu(d, view, cluster_error * MeanMass(d));
    EXPECT_NEAR(static_cast<double>(p.stats.points_drawn), static_cast<double>(cpu), 1e-4 * static_cast<double>(cpu) + 1);
    EXPECT_NEAR(Total(*p.hdr) / Total(*reference.hdr), 1, 1e-3);
    EXPECT_LE(p.stats.points_drawn, previous);
    previous = p.stats.points_drawn;
    if (cluster_error < 1e-100) {
      EXPECT_EQ(p.stats.points_drawn, scene->particles);
      EXPECT_LT(testing_support::RelativeL1(*p.hdr, *reference.hdr), 1e-6);
    }
    std::printf("cluster error %g: %llu points (CPU %llu), mass %+.2e\n", cluster_error,
                static_cast<unsigned long long>(p.stats.points_drawn), static_cast<unsigned long long>(cpu),
                Total(*p.hdr) / Total(*reference.hdr) - 1);
  }
  EXPECT_LT(previous, scene->particles / 20) << "a coarse cut takes few points";
}

// From inside, nodes out of view are not reached and their parents' clusters
// stand in: the mass in view stays the full-detail picture's within 1%
// (clusters near the view's edge spread their blobs differently), and the
// compute path draws what the raster path draws.
TEST_F(GlClusterCutTest, InsideTheBoxAndOnBothPaths) {
  const Dataset d = Dataset::Open(scene->store);
  const RenderView view = Inside(d);
  OffscreenRenderer full(d, HeadlessBackend::kOsMesa, Full());
  const double full_mass = Total(*full.Render(view, 0, {}, true).hdr);
  for (const double cluster_error : {3.0, 30.0, 300.0}) {
    SCOPED_TRACE("cluster error " + std::to_string(cluster_error));
    OffscreenRenderer raster(d, HeadlessBackend::kOsMesa, Cut(cluster_error));
    const Picture r = raster.Render(view, 0, {}, true);
    EXPECT_NEAR(Total(*r.hdr) / full_mass, 1, 0.01);
    EXPECT_LT(r.stats.points_drawn, scene->particles);
    SceneOptions o = Cut(cluster_error);
    o.splat_path = SplatPath::kCompute;
    OffscreenRenderer compute(d, HeadlessBackend::kOsMesa, o);
    if (!compute.splat().compute_supported()) continue;
    const Picture c = compute.Render(view, 0, {}, true);
    EXPECT_EQ(c.stats.points_drawn, r.stats.points_drawn);
    EXPECT_LT(testing_support::RelativeL1(*c.hdr, *r.hdr), 1e-5);
  }
}

// Streamed frames draw what has arrived: each frame is whole (the mass of
// the complete frame, parents standing in for children on their way), and
// once everything has arrived the frame is the complete one.
TEST_F(GlClusterCutTest, StreamedFramesAreWholeAndConverge) {
  const Dataset d = Dataset::Open(scene->store);
  const RenderView view = Overview(d);
  OffscreenRenderer complete(d, HeadlessBackend::kOsMesa, Cut(3));
  const Picture target = complete.Render(view, 0, {}, true);
  OffscreenRenderer streamed(d, HeadlessBackend::kOsMesa, Cut(3));
  FrameStats stats;
  int frames = 0;
  for (; frames < 2000; ++frames) {
    stats = streamed.scene().Stream(view, 0, false);
    const HdrImage image = streamed.splat().ReadHdr();
    if (stats.points_drawn > 0) {
      EXPECT_NEAR(Total(image) / Total(*target.hdr), 1, 1e-3) << "frame " << frames;
    }
    if (stats.blocks_missing == 0 && stats.blocks_uploaded == 0 && stats.stand_ins == 0) {
      EXPECT_LT(testing_support::RelativeL1(image, *target.hdr), 1e-6);
      break;
    }
  }
  EXPECT_LT(frames, 2000) << "the stream converges";
}

// The point budget holds: the nodes reached hold at most that many points,
// and the cut within them still carries the whole mass.
TEST_F(GlClusterCutTest, ThePointBudgetHolds) {
  const Dataset d = Dataset::Open(scene->store);
  const RenderView view = Overview(d);
  OffscreenRenderer full(d, HeadlessBackend::kOsMesa, Full());
  const double full_mass = Total(*full.Render(view, 0, {}, true).hdr);
  SceneOptions o = Cut(1e-300);
  o.lod.point_budget = scene->particles / 10;
  OffscreenRenderer cut(d, HeadlessBackend::kOsMesa, o);
  const Picture p = cut.Render(view, 0, {}, true);
  EXPECT_TRUE(p.stats.budget_reached);
  EXPECT_LE(p.stats.points_selected, o.lod.point_budget);
  EXPECT_LE(p.stats.points_drawn, o.lod.point_budget);
  EXPECT_NEAR(Total(*p.hdr) / full_mass, 1, 1e-3);
}

}  // namespace
}  // namespace octocosm
