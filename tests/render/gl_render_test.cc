// The OpenGL renderer against the CPU reference, on OSMesa (ctest label
// "gl"): a clustered snapshot is generated, ingested, and drawn both ways.
// Each test states its tolerance and why it is that large.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <thread>

#include "ingest/ingest.h"
#include "query/particle_lookup.h"
#include "render/image_metrics.h"
#include "render/offscreen_renderer.h"
#include "render/reference_rasterizer.h"
#include "render/selection_set.h"
#include "synth/scale_generator.h"
#include "tests/support/hdr_compare.h"
#include "tests/support/render_scene.h"
#include "tests/support/temp_dir.h"
#include "tools/camera_flags.h"
#include "tools/reference_render.h"

namespace octocosm {
namespace {

using testing_support::RenderScene;

RenderScene* scene = nullptr;

class GlRenderTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { scene = testing_support::MakeRenderScene("gl-render-test", 200000, 2, 3, 4000); }
  static void TearDownTestSuite() {
    delete scene;
    scene = nullptr;
  }

  static RenderView Overview(const Dataset& d, int width = 320, int height = 180) {
    return testing_support::OverviewOf(d, width, height);
  }
  static RenderView Inside(const Dataset& d, int width = 320, int height = 180) {
    return testing_support::InsideOf(d, width, height);
  }

  static SceneOptions Full() {
    SceneOptions o;
    o.lod.pixel_threshold = 1e-9;
    return o;
  }

  static HdrImage Reference(const RenderView& view, const SelectionSet* selection = nullptr) {
    ReferenceRenderOptions options;
    options.selection = selection;
    options.threads = 2;
    options.smoothing.quiet = true;
    return RenderReference(scene->snapshot, view, options);
  }
};

double Total(const HdrImage& image, int channel = 0) {
  double sum = 0;
  for (std::size_t i = static_cast<std::size_t>(channel); i < image.rgba.size(); i += 4) sum += image.rgba[i];
  return sum;
}

using testing_support::RelativeL1;

// At full detail the GPU draws every particle, from 16-bit node-relative
// positions in float, with float sums: against the CPU's double-precision
// drawing of the snapshot the mass images agree to 1e-3 relative L1 and the
// total to 1e-4 (measured: ~1e-5 and ~1e-7), and the pictures, tone mapped
// with the same exposure, to PSNR 60 dB.
TEST_F(GlRenderTest, FullDetailMatchesTheReference) {
  const Dataset d = Dataset::Open(scene->store);
  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, Full());
  for (const bool outside : {true, false}) {
    const RenderView view = outside ? Overview(d) : Inside(d);
    const Picture gpu = renderer.Render(view, 0, {}, true);
    const HdrImage reference = Reference(view);
    if (outside) {
      EXPECT_EQ(gpu.stats.points_drawn, scene->particles) << "every particle, at full detail";
    } else {
      // Octants whose blobs cannot reach the view are left out, and only those.
      EXPECT_LT(gpu.stats.points_drawn, gpu.stats.points_selected);
    }
    EXPECT_NEAR(Total(*gpu.hdr) / Total(reference), 1, 1e-4);
    EXPECT_LT(RelativeL1(*gpu.hdr, reference), 1e-3);
    EXPECT_GT(Psnr(ToneMap(*gpu.hdr, gpu.tone), ToneMap(reference, gpu.tone)), 60);
  }
}

// Every level of detail carries the whole mass: the weights of a node sum to
// its subtree's. From outside, with all of the box in view, the image's total
// is the dataset's mass to 1e-3 (blob normalization, 4.1e-4 at most, and
// float sums; measured 3e-7). From inside, the mass that falls in view depends
// on where the sampled points lie inside the nodes the frustum cuts: within
// 1% of the full rendering's (sampling error; measured at most 0.22%).
TEST_F(GlRenderTest, MassIsConservedAtEveryLevelOfDetail) {
  const Dataset d = Dataset::Open(scene->store);
  OffscreenRenderer full(d, HeadlessBackend::kOsMesa, Full());
  const double overview_full = Total(*full.Render(Overview(d), 0, {}, true).hdr);
  const double inside_full = Total(*full.Render(Inside(d), 0, {}, true).hdr);
  EXPECT_NEAR(overview_full / d.summary(0).mass.value(), 1, 1e-3);
  for (const auto& [threshold, budget] : std::vector<std::pair<double, std::uint64_t>>{
           {32, 0}, {8, 0}, {2, 0}, {1, 40000}, {0.5, 80000}}) {
    SceneOptions o;
    o.lod.pixel_threshold = threshold;
    o.lod.point_budget = budget;
    OffscreenRenderer lod(d, HeadlessBackend::kOsMesa, o);
    const Picture outside = lod.Render(Overview(d), 0, {}, true);
    const Picture inside = lod.Render(Inside(d), 0, {}, true);
    SCOPED_TRACE("threshold " + std::to_string(threshold) + ", budget " + std::to_string(budget));
    EXPECT_LT(outside.stats.points_drawn, scene->particles);
    if (budget > 0) {
      EXPECT_LE(outside.stats.points_drawn, budget);
    }
    EXPECT_NEAR(Total(*outside.hdr) / overview_full, 1, 1e-3);
    EXPECT_NEAR(Total(*inside.hdr) / inside_full, 1, 0.01);
    std::printf("threshold %g, budget %llu: %llu points; mass outside %+.2e, inside %+.2e\n", threshold,
                static_cast<unsigned long long>(budget), static_cast<unsigned long long>(inside.stats.points_drawn),
                Total(*outside.hdr) / overview_full - 1, Total(*inside.hdr) / inside_full - 1);
  }
}

// The GPU's tone mapping computes in float what the CPU computes in double:
// at most one 8-bit level apart.
TEST_F(GlRenderTest, GpuToneMappingMatchesTheCpu) {
  const Dataset d = Dataset::Open(scene->store);
  SceneOptions o;
  o.lod.pixel_threshold = 2;
  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, o);
  for (ToneCurve curve : {ToneCurve::kLog, ToneCurve::kAsinh}) {
    for (ColorMode color : {ColorMode::kDensity, ColorMode::kSpeed, ColorMode::kLineOfSightVelocity,
                            ColorMode::kVelocityDispersion, ColorMode::kType}) {
      ToneMapSettings tone;
      tone.curve = curve;
      tone.color = color;
      tone.attribute_map = color == ColorMode::kLineOfSightVelocity ? ColorMapId::kCoolwarm : ColorMapId::kViridis;
      const Picture p = renderer.Render(Overview(d), 0, tone, true);
      const RgbImage cpu = ToBytes(ToneMap(*p.hdr, p.tone));
      int worst = 0;
      for (std::size_t i = 0; i < cpu.rgb.size(); ++i) worst = std::max(worst, std::abs(cpu.rgb[i] - p.rgb.rgb[i]));
      EXPECT_LE(worst, 1) << ToneCurveName(curve) << " " << ColorModeName(color);
    }
  }
}

// The GPU's image statistics (compute shaders, float) against MeasureImage:
// the largest density agrees to float rounding, the automatic exposure to a
// histogram bin (1/32 octave).
TEST_F(GlRenderTest, GpuImageStatisticsMatchTheCpu) {
  const Dataset d = Dataset::Open(scene->store);
  SceneOptions o;
  o.lod.pixel_threshold = 1;
  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, o);
  renderer.scene().SetColorMode(ColorMode::kSpeed);
  renderer.scene().Complete(Inside(d), 0);
  const ImageStatistics gpu = renderer.splat().Measure();
  const ImageStatistics cpu = MeasureImage(renderer.splat().ReadHdr(), ColorMode::kSpeed);
  EXPECT_NEAR(gpu.max_density / cpu.max_density, 1, 1e-6);
  EXPECT_NEAR(gpu.attribute_min, cpu.attribute_min, 1e-3 * std::fabs(cpu.attribute_max));
  EXPECT_NEAR(gpu.attribute_max, cpu.attribute_max, 1e-3 * std::fabs(cpu.attribute_max));
  ToneMapSettings settings;
  EXPECT_NEAR(std::log2(AutomaticExposure(settings, gpu) / AutomaticExposure(settings, cpu)), 0, 1.0 / 32);
  const std::uint32_t gpu_lit = std::accumulate(gpu.density.begin(), gpu.density.end(), 0u);
  const std::uint32_t cpu_lit = std::accumulate(cpu.density.begin(), cpu.density.end(), 0u);
  EXPECT_EQ(gpu_lit, cpu_lit);
}

// A frame that repeats the one before, tone mapped by the statistics the GPU
// finished last (the render loop's way), is the picture measured and waited
// for; the first frame, with no statistics finished yet, waits for its own.
// (Whether a frame's own statistics are finished by the time it tone maps
// depends on the GPU; either gives this picture.)
TEST_F(GlRenderTest, LatestStatisticsToneMapARepeatedFrameAsItsOwnDo) {
  const Dataset d = Dataset::Open(scene->store);
  SceneOptions o;
  o.lod.pixel_threshold = 2;
  OffscreenRenderer waited(d, HeadlessBackend::kOsMesa, o);
  const Picture expected = waited.Render(Inside(d), 0, {}, false);
  OffscreenRenderer looped(d, HeadlessBackend::kOsMesa, o);
  looped.SetStatisticsTiming(StatisticsTiming::kLatest);
  const Picture first = looped.Render(Inside(d), 0, {}, false);
  const Picture second = looped.Render(Inside(d), 0, {}, false);
  EXPECT_EQ(first.tone.exposure, expected.tone.exposure);
  EXPECT_EQ(second.tone.exposure, expected.tone.exposure);
  EXPECT_EQ(second.rgb.rgb, expected.rgb.rgb);
}

// The measure's GPU time is its compute passes: the CPU reading the result
// before it tone maps (here, and 300 ms later) is in no stage.
TEST_F(GlRenderTest, GpuStageTimesLeaveOutTheWaitForTheStatistics) {
  const Dataset d = Dataset::Open(scene->store);
  SceneOptions o;
  o.lod.pixel_threshold = 8;
  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, o);
  renderer.scene().Complete(Overview(d, 64, 36), 0);
  const ImageStatistics measured = renderer.splat().Measure();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  renderer.splat().ToneMapToImage(ResolveToneMap({}, measured));
  renderer.splat().Finish();
  const std::optional<GpuStageTimes> times = renderer.splat().LatestGpuTimes(true);
  ASSERT_TRUE(times.has_value());
  EXPECT_GT(times->draw_ms, 0);
  EXPECT_LT(times->measure_ms, 250);
  EXPECT_LT(times->tone_map_ms, 250);
}

// A selection of 10^6 IDs, held on the GPU: half the store's particles plus
// IDs that are not in it. The highlighted mass (channel 3) equals the
// reference's, which tests each particle's ID exactly on the CPU, pixel by
// pixel (1e-3 relative L1) and in total (1e-4); IDs that are not in the store
// highlight nothing.
TEST_F(GlRenderTest, HighlightingAMillionIdsMarksExactlyTheSelectedParticles) {
  const Dataset d = Dataset::Open(scene->store);
  std::vector<std::uint64_t> ids;
  for (std::uint64_t id = 2; id <= scene->particles; id += 2) ids.push_back(id);
  std::mt19937_64 rng(9);
  while (ids.size() < 1000000) ids.push_back((rng() | (std::uint64_t{1} << 40)) >> 1);  // far above any ID here
  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, Full());
  renderer.scene().SetSelection(ids);
  EXPECT_EQ(renderer.scene().selection_size(), ids.size());
  const RenderView view = Overview(d);
  const Picture gpu = renderer.Render(view, 0, {}, true);
  const SelectionSet selection(ids);
  const HdrImage reference = Reference(view, &selection);
  ASSERT_GT(Total(reference, 3), 0.3 * Total(reference, 0));
  EXPECT_NEAR(Total(*gpu.hdr, 3) / Total(reference, 3), 1, 1e-4);
  EXPECT_LT(RelativeL1(*gpu.hdr, reference, 3), 1e-3);

  const std::vector<std::uint64_t> absent(ids.begin() + static_cast<std::ptrdiff_t>(scene->particles / 2), ids.end());
  renderer.scene().SetSelection(absent);
  EXPECT_EQ(Total(*renderer.Render(view, 0, {}, true).hdr, 3), 0.0);
}

// Highlighting is exact at any level of detail: the selected particles are
// drawn at full detail into the highlight channel, so its mass image equals
// the reference's however few points draw the rest (same tolerances as the
// full-detail selection above), while the density channel is the level of
// detail's own, unchanged by the selection (to float rounding). A streamed frame highlights
// exactly once the look-up has finished.
TEST_F(GlRenderTest, HighlightingIsExactAtACoarseLevelOfDetail) {
  const Dataset d = Dataset::Open(scene->store);
  std::vector<std::uint64_t> ids;
  for (std::uint64_t id = 1; id <= scene->particles; id += 7) ids.push_back(id);
  SceneOptions coarse;
  coarse.lod.point_budget = scene->particles / 20;
  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, coarse);
  for (const bool outside : {true, false}) {
    SCOPED_TRACE(outside ? "overview" : "inside");
    const RenderView view = outside ? Overview(d) : Inside(d);
    renderer.scene().SetSelection({});
    const Picture plain = renderer.Render(view, 0, {}, true);
    renderer.scene().SetSelection(ids);
    const Picture lod = renderer.Render(view, 0, {}, true);
    ASSERT_LE(lod.stats.points_drawn, scene->particles / 20);
    EXPECT_TRUE(lod.stats.highlight_exact);
    EXPECT_EQ(lod.stats.points_highlighted, ids.size());
    const SelectionSet selection(ids);
    const HdrImage reference = Reference(view, &selection);
    ASSERT_GT(Total(reference, 3), 0.05 * Total(reference, 0));
    EXPECT_NEAR(Total(*lod.hdr, 3) / Total(reference, 3), 1, 1e-4);
    EXPECT_LT(RelativeL1(*lod.hdr, reference, 3), 1e-3);
    // Unchanged but for the order of float additions (the compute path's
    // atomics add in no fixed order).
    EXPECT_LT(RelativeL1(*lod.hdr, *plain.hdr, 0), 1e-6);
  }

  // Streamed: a new selection is looked up in the background.
  renderer.scene().SetSelection(ids);
  const RenderView view = Overview(d);
  FrameStats streamed;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  do {
    streamed = renderer.scene().Stream(view, 0, false);
  } while ((!streamed.highlight_exact || streamed.blocks_missing > 0) && std::chrono::steady_clock::now() < deadline);
  EXPECT_TRUE(streamed.highlight_exact) << renderer.scene().last_error();
  EXPECT_EQ(streamed.points_highlighted, ids.size());
}

// Coloured by line-of-sight velocity dispersion, a pixel's third channel
// sums mass x (v_los^2 + sigma^2): a cluster brings its members' dispersion,
// so over the whole overview a coarse frame carries the full frame's second
// moment (within 3%: a cluster's dispersion is taken as the same along every
// axis; measured 0.4%), where mean velocities alone carry 47% of it.
TEST_F(GlRenderTest, CoarseFramesKeepTheVelocitySecondMoment) {
  const Dataset d = Dataset::Open(scene->store);
  ASSERT_TRUE(d.cluster_columns() & ColumnBit(ColumnId::kVelocityDispersion));
  const RenderView view = Overview(d);
  ToneMapSettings tone;
  tone.color = ColorMode::kVelocityDispersion;
  SceneOptions full = Full(), coarse;
  coarse.lod.point_budget = scene->particles / 50;
  const Picture all = OffscreenRenderer(d, HeadlessBackend::kOsMesa, full).Render(view, 0, tone, true);
  const Picture few = OffscreenRenderer(d, HeadlessBackend::kOsMesa, coarse).Render(view, 0, tone, true);
  ASSERT_LE(few.stats.points_drawn, scene->particles / 50);
  EXPECT_NEAR(Total(*few.hdr, 0) / Total(*all.hdr, 0), 1, 1e-3);
  EXPECT_NEAR(Total(*few.hdr, 2) / Total(*all.hdr, 2), 1, 0.03);
}

// The viewer's path: frames never wait for the disk. Once the root has
// arrived every frame carries the whole mass (parents stand in for children
// on their way: their octant ranges are a sample of the same subtree, so
// within the sampling error, 3%; measured at most 1.6%), and once everything
// has arrived the frame is the complete one.
TEST_F(GlRenderTest, StreamedFramesConserveMassWhileBlocksArrive) {
  const Dataset d = Dataset::Open(scene->store);
  SceneOptions o;
  o.lod.pixel_threshold = 0.5;
  o.upload_bytes_per_frame = 64 << 10;  // a few blocks per frame
  o.io_threads = 1;
  OffscreenRenderer complete(d, HeadlessBackend::kOsMesa, o);
  const RenderView view = Overview(d);
  const double whole = Total(*complete.Render(view, 0, {}, true).hdr);

  OffscreenRenderer streaming(d, HeadlessBackend::kOsMesa, o);
  FrameStats stats;
  int frames_with_stand_ins = 0;
  double worst = 0;
  for (int frame = 0; frame < 2000; ++frame) {
    stats = streaming.scene().Stream(view, 0, false);
    const double total = Total(streaming.splat().ReadHdr());
    if (stats.points_drawn > 0) {
      EXPECT_NEAR(total / whole, 1, 0.03) << "frame " << frame;
      worst = std::max(worst, std::fabs(total / whole - 1));
    }
    frames_with_stand_ins += stats.stand_ins > 0;
    if (stats.blocks_missing == 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  EXPECT_EQ(stats.blocks_missing, 0u);
  EXPECT_GT(frames_with_stand_ins, 0);
  EXPECT_EQ(stats.stand_ins, 0u);
  EXPECT_NEAR(Total(streaming.splat().ReadHdr()) / whole, 1, 1e-5);
  std::printf("streaming: %d frames with stand-ins, worst mass error %.2e\n", frames_with_stand_ins, worst);
}

// 10^7 blobs accumulated into one pixel. Float sums (RGBA32F
// blending) against the double sum: relative error below 1e-4 (measured
// 9.4e-6 on llvmpipe).
TEST_F(GlRenderTest, TenMillionBlobsInOnePixelSumToTheDoubleReference) {
  const Dataset d = Dataset::Open(scene->store);  // any dataset: only its context is used
  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, Full());
  // One node of a unit cube holding 10^6 points at its centre, with weights
  // between 0.5 and 1.5 (times 10^-6) and a tiny smoothing length: each blob
  // has the smallest radius, 1 pixel, centred on a pixel centre, so it adds
  // its whole weight to that one pixel. Drawn ten times.
  const Cube cube{{0, 0, 0}, 1, false};
  const NodeKey key = NodeKey::Root();
  NodePoints points;
  const std::size_t n = 1000000;
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> w(0.5e-6, 1.5e-6);
  double sum = 0;
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) points.position.push_back(0.5 + 0.25 / 65536);  // the centre of a quantum
    points.weight.push_back(w(rng));
    sum += points.weight.back();
    points.smoothing.push_back(1e-6);
    points.type.push_back(1);
  }
  OrderByOctant(points, key, cube);
  const Bytes bytes = EncodeBlock(points, key, cube);
  const BlockHeader header = DecodeBlockHeader(bytes, key, "test");
  const GpuBlock block = GpuBlock::Upload(renderer.splat().blocks(), bytes, header, cube.NodeCubeOf(key), "test");
  // The decoded weights are what the GPU adds: sum them in double.
  const DecodedBlock decoded = DecodeBlock(bytes, kAllColumns, key, cube, "test");
  const double expected = 10 * std::accumulate(decoded.points.weight.begin(), decoded.points.weight.end(), 0.0);
  EXPECT_NEAR(expected / (10 * sum), 1, 1e-9);

  Camera camera;
  camera.position = {decoded.points.position[0], decoded.points.position[1], 3};
  camera.look_at = {decoded.points.position[0], decoded.points.position[1], 0};
  camera.near = 0.1;
  camera.far = 10;
  const RenderView view(camera, 64, 64);  // the centre projects to (32, 32): a pixel corner...
  // ...so shift the camera by half a pixel to put it on a pixel centre.
  const double half_pixel = 0.5 / view.focal_pixels() * (3 - decoded.points.position[2]);
  camera.position[0] -= half_pixel;
  camera.position[1] -= half_pixel;
  camera.look_at[0] -= half_pixel;
  camera.look_at[1] -= half_pixel;
  const RenderView centred(camera, 64, 64);
  for (SplatPath path : {SplatPath::kRaster, SplatPath::kCompute}) {
    FrameSettings settings;
    settings.mass_unit = 1e-6;
    settings.path = path;
    renderer.splat().BeginFrame(centred, settings);
    for (int k = 0; k < 10; ++k) renderer.splat().Draw(block, 0, block.point_count());
    const HdrImage image = renderer.splat().ReadHdr();
    EXPECT_NEAR(image.at(32, 32, 0) / expected, 1, 1e-4) << SplatPathName(path);
    EXPECT_NEAR(Total(image) / expected, 1, 1e-4) << SplatPathName(path);
    std::printf("10^7 blobs in one pixel, %s path: float sum %.9g, double sum %.9g, relative error %.3g\n",
                SplatPathName(renderer.splat().frame_path()), image.at(32, 32, 0), expected,
                image.at(32, 32, 0) / expected - 1);
  }
}

// The id column reaches the GPU as stored: u32 offsets from the block's base
// (the shader adds them, carrying into the high word) or whole u64 IDs.
// Blocks whose IDs cross 2^32, end at 2^64 - 2, or span more than 2^32 (so
// stored whole); every other ID selected: the highlighted mass is the mass of
// exactly those points.
TEST_F(GlRenderTest, HighlightingReadsIdOffsetsAcross32BitsAndWholeIds) {
  const Dataset d = Dataset::Open(scene->store);  // any dataset: only its context is used
  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, Full());
  const Cube cube{{0, 0, 0}, 1, false};
  const NodeKey key = NodeKey::Root();
  constexpr std::uint64_t kCarry = std::uint64_t{1} << 32;
  constexpr std::uint64_t kLast = std::numeric_limits<std::uint64_t>::max() - 1;  // 2^64 - 1 cannot be selected
  struct Case {
    std::uint64_t first, step;
    int encoding;
  };
  for (const Case& c : {Case{kCarry - 500, 1, 2}, Case{kLast - 999, 1, 2}, Case{7, kCarry / 100, 1}}) {
    NodePoints points;
    std::mt19937_64 rng(c.first);
    std::uniform_real_distribution<double> w(0.5, 1.5);
    for (std::uint64_t i = 0; i < 1000; ++i) {
      for (int a = 0; a < 3; ++a) points.position.push_back(0.5 + 0.25 / 65536);
      points.weight.push_back(w(rng));
      points.smoothing.push_back(1e-6);
      points.type.push_back(1);
      points.id.push_back(c.first + i * c.step);
    }
    OrderByOctant(points, key, cube);
    const Bytes bytes = EncodeBlock(points, key, cube);
    const BlockHeader header = DecodeBlockHeader(bytes, key, "test");
    ASSERT_EQ(header.Find(ColumnId::kId)->encoding, c.encoding) << c.first;
    const GpuBlock block = GpuBlock::Upload(renderer.splat().blocks(), bytes, header, cube.NodeCubeOf(key), "test");
    const DecodedBlock decoded = DecodeBlock(bytes, kAllColumns, key, cube, "test");
    std::vector<std::uint64_t> selected;
    double all = 0, selected_mass = 0;
    for (std::size_t i = 0; i < decoded.points.size(); ++i) {
      all += decoded.points.weight[i];
      if ((decoded.points.id[i] - c.first) / c.step % 2 == 0) {
        selected.push_back(decoded.points.id[i]);
        selected_mass += decoded.points.weight[i];
      }
    }
    SelectionSet selection(selected);
    selection.Upload();

    Camera camera;
    camera.position = {0.5, 0.5, 3};
    camera.look_at = {0.5, 0.5, 0};
    camera.near = 0.1;
    camera.far = 10;
    for (SplatPath path : {SplatPath::kRaster, SplatPath::kCompute}) {
      FrameSettings settings;
      settings.mass_unit = 1.0;
      settings.path = path;
      renderer.splat().BeginFrame(RenderView(camera, 64, 64), settings);
      renderer.splat().SetSelection(&selection);
      renderer.splat().Draw(block, 0, block.point_count());
      const HdrImage image = renderer.splat().ReadHdr();
      renderer.splat().SetSelection(nullptr);
      EXPECT_NEAR(Total(image, 0) / all, 1, 1e-5) << c.first << " " << SplatPathName(path);
      EXPECT_NEAR(Total(image, 3) / selected_mass, 1, 1e-5) << c.first << " " << SplatPathName(path)
                                                            << ": the highlighted mass";
    }
  }
}

// The largest |a - b| over pixels and channels, relative to |b| plus 10^-5
// of the channel's largest |value| (so that the faint edges of blobs, and
// pixels where signed line-of-sight velocities cancel, where float rounding
// is larger than the value, do not dominate).
double LargestRelativeDifference(const HdrImage& a, const HdrImage& b) {
  double worst = 0;
  for (int channel = 0; channel < 4; ++channel) {
    double brightest = 0;
    for (std::size_t i = static_cast<std::size_t>(channel); i < b.rgba.size(); i += 4) {
      brightest = std::max(brightest, static_cast<double>(std::fabs(b.rgba[i])));
    }
    for (std::size_t i = static_cast<std::size_t>(channel); i < b.rgba.size(); i += 4) {
      const double difference = std::fabs(double{a.rgba[i]} - b.rgba[i]);
      worst = std::max(worst, difference / (std::fabs(b.rgba[i]) + 1e-5 * brightest + 1e-300));
    }
  }
  return worst;
}

// The compute path (render/compute_splatter.h) draws the raster path's
// blobs into the same pixels with the same weights, added in another order:
// the images agree per pixel and channel to float rounding (1e-4 relative,
// LargestRelativeDifference), in every colour mode, with clusters drawn with their
// shapes and dispersions, with highlighted particles, from outside and
// inside the box.
TEST_F(GlRenderTest, ComputePathMatchesTheRasterPath) {
  const Dataset d = Dataset::Open(scene->store);
  std::vector<std::uint64_t> ids;
  for (std::uint64_t id = 1; id <= scene->particles; id += 5) ids.push_back(id);
  for (const double threshold : {1e-9, 2.0}) {
    SceneOptions options;
    options.lod.pixel_threshold = threshold;
    OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, options);
    if (!renderer.splat().compute_supported()) GTEST_SKIP() << "this GL has no float atomics";
    renderer.scene().SetSelection(ids);
    for (const bool outside : {true, false}) {
      const RenderView view = outside ? Overview(d) : Inside(d);
      for (ColorMode color : {ColorMode::kDensity, ColorMode::kSpeed, ColorMode::kLineOfSightVelocity,
                              ColorMode::kVelocityDispersion, ColorMode::kType}) {
        SCOPED_TRACE(std::string(outside ? "overview" : "inside") + ", threshold " + std::to_string(threshold) + ", " +
                     ColorModeName(color));
        ToneMapSettings tone;
        tone.color = color;
        renderer.scene().SetSplatPath(SplatPath::kRaster);
        const Picture raster = renderer.Render(view, 0, tone, true);
        EXPECT_EQ(renderer.splat().frame_path(), SplatPath::kRaster);
        renderer.scene().SetSplatPath(SplatPath::kCompute);
        const Picture compute = renderer.Render(view, 0, tone, true);
        EXPECT_EQ(renderer.splat().frame_path(), SplatPath::kCompute);
        ASSERT_EQ(compute.stats.points_drawn, raster.stats.points_drawn);
        ASSERT_TRUE(compute.stats.highlight_exact);
        const double difference = LargestRelativeDifference(*compute.hdr, *raster.hdr);
        EXPECT_LT(difference, 1e-4);
        EXPECT_NEAR(Total(*compute.hdr, 3) / Total(*raster.hdr, 3), 1, 1e-6);
        std::printf("%s, threshold %g, %s: largest relative difference %.2e\n", outside ? "overview" : "inside",
                    threshold, ColorModeName(color), difference);
      }
    }
  }
}

// Blobs above the compute radius are listed and added after the dispatch by a
// workgroup each; when the list is full the thread adds its blob itself. Inside
// the box, with radii of 1 to tens of pixels: the same image whatever the
// radius (0: every blob by a workgroup; 1000: none) and with a list of 16 blobs.
TEST_F(GlRenderTest, ComputePathAddsLargeBlobsByWorkgroupAndNeverLosesOne) {
  const Dataset d = Dataset::Open(scene->store);
  SceneOptions options = Full();
  options.splat_path = SplatPath::kRaster;
  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, options);
  if (!renderer.splat().compute_supported()) GTEST_SKIP() << "this GL has no float atomics";
  const RenderView view = Inside(d, 480, 270);
  const Picture raster = renderer.Render(view, 0, {}, true);
  for (const double radius : {0.0, 1.0, 4.0, 1000.0}) {
    for (const std::uint32_t capacity : {1u << 20, 16u}) {
      SCOPED_TRACE("compute radius " + std::to_string(radius) + ", list of " + std::to_string(capacity));
      SceneOptions o = options;
      o.splat_path = SplatPath::kCompute;
      o.compute_radius = radius;
      OffscreenRenderer compute(d, HeadlessBackend::kOsMesa, o);
      compute.splat().SetLargeBlobCapacity(capacity);
      const Picture p = compute.Render(view, 0, {}, true);
      EXPECT_EQ(compute.splat().frame_path(), SplatPath::kCompute);
      EXPECT_LT(LargestRelativeDifference(*p.hdr, *raster.hdr), 1e-4);
      EXPECT_NEAR(Total(*p.hdr) / Total(*raster.hdr), 1, 1e-6);
    }
  }
}

}  // namespace
}  // namespace octocosm
