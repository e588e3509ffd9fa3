// Time interpolation on the GPU (ctest label "gl"): two-epoch series are
// written as CSV, ingested with IDs (so the store links the epochs), and drawn
// between the epochs. Each test states its tolerance.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <random>
#include <thread>
#include <utility>

#include "ingest/ingest.h"
#include "render/offscreen_renderer.h"
#include "tests/support/hdr_compare.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

struct Particle {
  std::array<double, 3> position;
  std::array<double, 3> velocity;
};

void WriteCsv(const std::string& file, const std::vector<Particle>& particles) {
  std::ofstream out(file);
  out << "x,y,z,vx,vy,vz,mass,id\n";
  out.precision(17);
  for (std::size_t i = 0; i < particles.size(); ++i) {
    const Particle& p = particles[i];
    out << p.position[0] << ',' << p.position[1] << ',' << p.position[2] << ',' << p.velocity[0] << ','
        << p.velocity[1] << ',' << p.velocity[2] << ",1," << i + 1 << '\n';
  }
}

// Ingests the two epochs; box > 0 makes the store periodic with that box.
std::string IngestSeries(const testing_support::TempDir& dir, const std::vector<Particle>& first,
                         const std::vector<Particle>& second, double box, int neighbours = kDefaultNeighbours) {
  const std::string a = (dir.path() / "epoch0.csv").string();
  const std::string b = (dir.path() / "epoch1.csv").string();
  WriteCsv(a, first);
  WriteCsv(b, second);
  IngestOptions o;
  o.inputs = {a, b};
  o.output = (dir.path() / "store").string();
  o.tree.capacity = 500;  // several levels, so points are drawn from many nodes
  o.page_size = 16384;
  o.read.box_size_override = box;
  o.neighbours = neighbours;
  o.quiet = true;
  Ingest(o);
  return o.output;
}

// Looking down the z axis from far away at (50, 50): world x and y map to
// pixels almost linearly (the points lie within 1 of z = 50).
RenderView TopView() {
  Camera c;
  c.position = {50, 50, 450};
  c.look_at = {50, 50, 50};
  c.up = {0, 1, 0};
  c.near = 10;
  c.far = 1000;
  c.fov_y_degrees = 2 * std::atan(65.0 / 400.0) * 180 / M_PI;  // 130 units tall at z = 50
  return RenderView(c, 320, 208);
}

// The world coordinate in the plane z = 50 of a pixel centre.
std::array<double, 2> WorldOf(const RenderView& view, int i, int j) {
  const double scale = 400 / view.focal_pixels();
  return {50 + (i + 0.5 - view.width() / 2.0) * scale, 50 + (j + 0.5 - view.height() / 2.0) * scale};
}

struct MassMoments {
  double mass = 0, x = 0, y = 0;  // x and y: mass-weighted means
};

// The mass channel's moments over the pixels whose world x satisfies `where`.
template <typename Where>
MassMoments Moments(const HdrImage& image, const RenderView& view, Where where) {
  MassMoments m;
  for (int j = 0; j < image.height; ++j) {
    for (int i = 0; i < image.width; ++i) {
      const auto w = WorldOf(view, i, j);
      if (!where(w[0])) continue;
      const double v = image.at(i, j, 0);
      m.mass += v;
      m.x += v * w[0];
      m.y += v * w[1];
    }
  }
  if (m.mass > 0) m.x /= m.mass, m.y /= m.mass;
  return m;
}

double Total(const HdrImage& image) { return Moments(image, TopView(), [](double) { return true; }).mass; }

using testing_support::RelativeL1;

// A tight clump of n particles around `centre`, all with velocity `v`.
std::vector<Particle> Clump(std::size_t n, std::array<double, 3> centre, std::array<double, 3> v, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> offset(0, 0.15);
  std::vector<Particle> out(n);
  for (Particle& p : out) {
    for (int a = 0; a < 3; ++a) p.position[a] = centre[a] + offset(rng);
    p.velocity = v;
  }
  return out;
}

SceneOptions FullDetail(Interpolation interpolation) {
  SceneOptions o;
  o.lod.pixel_threshold = 1e-9;
  o.interpolation = interpolation;
  return o;
}

// A clump crossing the periodic boundary at x = 100 moves 4 units to the
// right: from x ~ 97 to x ~ 1 (wrapped). Drawn at time t, the copy of epoch
// 0 (weight 1 - t) moves the short way forward, to p_0 + 4 t, and the copy of
// epoch 1 (weight t) the short way back, to p_1 - 4 (1 - t); both are drawn
// wrapped into the box [0, 100), so a particle past x = 100 appears near
// x = 0 and one below x = 0 near x = 100. Expected: no mass outside the box
// beyond a blob's radius (the clump's blobs are one pixel, 0.625 units);
// none in the middle of the box, where the long way (-96 units) would pass;
// in each half of the box the mass of both copies that the wrapped short way
// puts there, to 1e-3, centred where it puts it to 0.15 units in x (a
// quarter of a pixel: one-pixel blobs lean towards the nearest pixel centre,
// which the halves of a clump cut by a face, at a pixel edge, do not average
// out) and 0.1 in y.
TEST(GlInterpolation, PeriodicCrossingMovesTheShortWay) {
  testing_support::TempDir dir("gl-interpolation-periodic");
  const std::size_t n = 3000;
  const double box = 100;
  std::vector<Particle> first = Clump(n, {97, 40, 50}, {0, 0, 0}, 1);
  std::vector<Particle> second = first;
  for (Particle& p : second) p.position[0] = std::fmod(p.position[0] + 4, box);
  const std::string store = IngestSeries(dir, first, second, box);
  const Dataset d = Dataset::Open(store);
  ASSERT_TRUE(d.link_to_next(0).has_value());
  ASSERT_TRUE(d.cube(0).periodic);

  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, FullDetail(Interpolation::kLinear));
  const RenderView view = TopView();
  const double whole = Total(*renderer.Render(view, 0, {}, true).hdr);
  ASSERT_GT(whole, 0);
  const auto wrap = [&](double x) { return x - box * std::floor(x / box); };
  for (const double t : {0.25, 0.5, 0.75}) {
    SCOPED_TRACE("t = " + std::to_string(t));
    // Where the copies go: mass (as a share of the whole) and mass-weighted x per half.
    MassMoments expected_left, expected_right;
    for (std::size_t i = 0; i < n; ++i) {
      double d0 = second[i].position[0] - first[i].position[0];
      d0 -= box * std::round(d0 / box);  // the minimal image
      for (const auto& [x, weight] : {std::pair{first[i].position[0] + t * d0, (1 - t) / n},
                                      std::pair{second[i].position[0] - (1 - t) * d0, t / n}}) {
        MassMoments& side = wrap(x) < box / 2 ? expected_left : expected_right;
        side.mass += weight;
        side.x += weight * wrap(x);
      }
    }
    const Picture p = renderer.Render(view, t, {}, true);
    EXPECT_EQ(p.stats.interpolation, Interpolation::kLinear);
    EXPECT_EQ(p.stats.epochs_drawn, 2u);
    const double blob = 400 / view.focal_pixels();  // one pixel, in world units at z = 50
    const MassMoments outside = Moments(*p.hdr, view, [&](double x) { return x < -blob || x > box + blob; });
    const MassMoments middle = Moments(*p.hdr, view, [](double x) { return x > 10 && x < 90; });
    const MassMoments right = Moments(*p.hdr, view, [](double x) { return x >= 50; });
    const MassMoments left = Moments(*p.hdr, view, [](double x) { return x < 50; });
    EXPECT_EQ(outside.mass, 0.0);
    EXPECT_EQ(middle.mass, 0.0);
    EXPECT_NEAR(right.mass / whole, expected_right.mass, 1e-3);
    EXPECT_NEAR(left.mass / whole, expected_left.mass, 1e-3);
    for (const auto& [side, expected] : {std::pair{right, expected_right}, std::pair{left, expected_left}}) {
      if (expected.mass < 1e-3) continue;
      EXPECT_NEAR(side.x, expected.x / expected.mass, 0.15);
      EXPECT_NEAR(side.y, 40, 0.1);
    }
  }
}

// A clump whose velocity turns from (1, 1, 0) to (1, -1, 0) while it moves
// 20 units along x, among 4000 background particles whose displacements
// agree with their velocities the same way (d = s (v0 + v1) / 2, s = 20):
// ingest fits s = 20 with no residual, and the renderer draws the cubic
// Hermite curve. At time t the clump's centre must be at
//   x = 40 + 20 (h01 + h10 + h11),  y = 50 + 20 (h10 - h11)
// (h the Hermite basis; y = 55 at t = 1/2, where a straight line stays at
// 50), from both copies alike: to 0.1 units.
TEST(GlInterpolation, HermiteFollowsTheVelocities) {
  testing_support::TempDir dir("gl-interpolation-hermite");
  const double s = 20;
  std::vector<Particle> first = Clump(3000, {40, 50, 50}, {1, 1, 0}, 2);
  std::vector<Particle> second = first;
  for (Particle& p : second) {
    p.position[0] += s;
    p.velocity = {1, -1, 0};
  }
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> where(0, 100), speed(-0.1, 0.1);
  for (int i = 0; i < 4000; ++i) {
    Particle a, b;
    for (int k = 0; k < 3; ++k) {
      a.position[k] = where(rng);
      a.velocity[k] = speed(rng);
      b.velocity[k] = speed(rng);
      b.position[k] = a.position[k] + s * (a.velocity[k] + b.velocity[k]) / 2;
    }
    // Keep the background away from the clump's path.
    if (a.position[1] > 35 && a.position[1] < 70) continue;
    first.push_back(a);
    second.push_back(b);
  }
  // Leaves' lengths from their density grid: the sparse background's radii
  // of 32 neighbours (about 15) would reach into the clump's window.
  const std::string store = IngestSeries(dir, first, second, 0, 0);
  const Dataset d = Dataset::Open(store);
  ASSERT_TRUE(d.link_to_next(0).has_value());
  EXPECT_NEAR(d.link_to_next(0)->velocity_scale, s, 1e-3 * s);
  EXPECT_LT(d.link_to_next(0)->fit_residual, 1e-3);

  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, FullDetail(Interpolation::kHermite));
  const RenderView view = TopView();
  for (const double t : {0.25, 0.5, 0.75}) {
    SCOPED_TRACE("t = " + std::to_string(t));
    const Picture p = renderer.Render(view, t, {}, true);
    EXPECT_EQ(p.stats.interpolation, Interpolation::kHermite);
    // The clump alone: the background stays outside 35 < y < 70.
    MassMoments clump;
    for (int j = 0; j < p.hdr->height; ++j) {
      for (int i = 0; i < p.hdr->width; ++i) {
        const auto w = WorldOf(view, i, j);
        if (w[1] <= 37 || w[1] >= 68) continue;
        const double v = p.hdr->at(i, j, 0);
        clump.mass += v;
        clump.x += v * w[0];
        clump.y += v * w[1];
      }
    }
    ASSERT_GT(clump.mass, 0);
    clump.x /= clump.mass;
    clump.y /= clump.mass;
    const double h10 = t * t * t - 2 * t * t + t, h11 = t * t * t - t * t, h01 = -2 * t * t * t + 3 * t * t;
    EXPECT_NEAR(clump.x, 40 + s * (h01 + h10 + h11), 0.1);
    EXPECT_NEAR(clump.y, 50 + s * (h10 - h11), 0.1);
  }
}

// At the ends of the interval the interpolated frame is the epoch's own: a
// time a millionth after epoch 0 (both copies drawn, epoch 1's with weight
// 1e-6) and a millionth before epoch 1 give the epochs' pictures to 1e-4
// relative L1 (the points move by a millionth of their paths), for linear
// and Hermite paths, in a periodic box that many of them cross.
// Two epochs of n particles spread over a periodic box of 100, moving up to
// 3 units between them (many cross a face).
std::string RandomPeriodicSeries(testing_support::TempDir& dir, int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> where(0, 100), speed(-1, 1);
  std::vector<Particle> first, second;
  for (int i = 0; i < n; ++i) {
    Particle a, b;
    for (int k = 0; k < 3; ++k) {
      a.position[k] = where(rng);
      a.velocity[k] = speed(rng);
      b.velocity[k] = speed(rng);
      b.position[k] = std::fmod(a.position[k] + 3 * (a.velocity[k] + b.velocity[k]) / 2 + 100, 100.0);
    }
    first.push_back(a);
    second.push_back(b);
  }
  return IngestSeries(dir, first, second, 100);
}

TEST(GlInterpolation, EndsOfTheIntervalReproduceTheEpochs) {
  testing_support::TempDir dir("gl-interpolation-ends");
  const Dataset d = Dataset::Open(RandomPeriodicSeries(dir, 20000, 4));
  for (const Interpolation mode : {Interpolation::kLinear, Interpolation::kHermite}) {
    SceneOptions o = FullDetail(mode);
    OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, o);
    const RenderView view = TopView();
    const HdrImage epoch0 = *renderer.Render(view, 0, {}, true).hdr;
    const HdrImage epoch1 = *renderer.Render(view, 1, {}, true).hdr;
    const Picture after0 = renderer.Render(view, 1e-6, {}, true);
    const Picture before1 = renderer.Render(view, 1 - 1e-6, {}, true);
    EXPECT_EQ(after0.stats.epochs_drawn, 2u);
    EXPECT_EQ(after0.stats.interpolation, mode);
    EXPECT_LT(RelativeL1(*after0.hdr, epoch0), 1e-4);
    EXPECT_LT(RelativeL1(*before1.hdr, epoch1), 1e-4);
    EXPECT_GT(RelativeL1(epoch1, epoch0), 0.03) << "the epochs differ (measured 0.054), so the comparison means something";
  }
}

// The compute path moves, wraps and colours the points as the raster path
// does (the same shader code, splat_point.glsl): interpolated frames, linear
// and Hermite, coloured by density and by speed, agree to float rounding
// (relative L1 1e-5 per channel; the sums differ in order only).
TEST(GlInterpolation, ComputePathInterpolatesAsTheRasterPath) {
  testing_support::TempDir dir("gl-interpolation-compute");
  const Dataset d = Dataset::Open(RandomPeriodicSeries(dir, 20000, 5));
  for (const Interpolation mode : {Interpolation::kLinear, Interpolation::kHermite}) {
    SceneOptions o = FullDetail(mode);
    OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, o);
    if (!renderer.splat().compute_supported()) GTEST_SKIP() << "this GL has no float atomics";
    for (const ColorMode color : {ColorMode::kDensity, ColorMode::kSpeed}) {
      ToneMapSettings tone;
      tone.color = color;
      for (const double t : {0.3, 0.5}) {
        SCOPED_TRACE(std::string(mode == Interpolation::kLinear ? "linear" : "Hermite") + ", " + ColorModeName(color) +
                     ", t = " + std::to_string(t));
        renderer.scene().SetSplatPath(SplatPath::kRaster);
        const Picture raster = renderer.Render(TopView(), t, tone, true);
        renderer.scene().SetSplatPath(SplatPath::kCompute);
        const Picture compute = renderer.Render(TopView(), t, tone, true);
        ASSERT_EQ(renderer.splat().frame_path(), SplatPath::kCompute);
        EXPECT_EQ(compute.stats.interpolation, mode);
        for (int channel = 0; channel < 3; ++channel) {
          if (color == ColorMode::kDensity && channel > 0) break;
          EXPECT_LT(RelativeL1(*compute.hdr, *raster.hdr, channel), 1e-5) << "channel " << channel;
        }
      }
    }
  }
}

// Playing forward, streamed frames read the next epoch's blocks ahead (its
// index loaded on a thread of its own, so that no frame waits for it): once
// the frames at epoch 0 have settled, drawing epoch 1 reads nothing more.
TEST(GlInterpolation, PlayingReadsTheNextEpochAhead) {
  testing_support::TempDir dir("gl-interpolation-ahead");
  const Dataset d = Dataset::Open(RandomPeriodicSeries(dir, 20000, 6));
  OffscreenRenderer renderer(d, HeadlessBackend::kOsMesa, FullDetail(Interpolation::kLinear));
  const RenderView view = TopView();
  std::uint64_t reads = 0;
  int unchanged = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (unchanged < 50 && std::chrono::steady_clock::now() < deadline) {
    const FrameStats stats = renderer.scene().Stream(view, 0, /*look_ahead=*/true);
    const std::uint64_t now = renderer.scene().disk_reads().blocks;
    unchanged = stats.blocks_missing == 0 && now == reads ? unchanged + 1 : 0;
    reads = now;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_EQ(unchanged, 50) << "the reads did not settle: " << renderer.scene().last_error();
  const Picture epoch1 = renderer.Render(view, 1, {}, true);
  EXPECT_EQ(epoch1.stats.epochs_drawn, 1u);
  EXPECT_GT(epoch1.stats.nodes_selected, 8u);
  EXPECT_EQ(renderer.scene().disk_reads().blocks, reads) << "epoch 1's blocks were not read ahead";
}

}  // namespace
}  // namespace octocosm
