// Tests of `synth scale`: the NFW sampling tables, and whole snapshots read
// back through the project's snapshot reader (ingest/snapshot) — counts, IDs,
// headers, periodic bounds, determinism across runs and thread counts, the
// radial profile of an isolated halo, and the clustering of the default mix.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <numeric>
#include <string>
#include <vector>

#include "index/particle_chunk.h"
#include "base/error.h"
#include "ingest/snapshot/snapshot_source.h"
#include "synth/cosmic_web.h"
#include "synth/nfw_profile.h"
#include "synth/scale_generator.h"
#include "synth/random.h"
#include "synth/scale_sampler.h"
#include "tests/support/temp_dir.h"

namespace octocosm::synth {
namespace {

namespace fs = std::filesystem;

using testing_support::LoadHostOrder;
using testing_support::ReadFileBytes;
using testing_support::TempDir;


ScaleOptions SmallOptions(const fs::path& dir) {
  ScaleOptions options;
  options.output_directory = dir.string();
  options.particle_count = 100'003;  // prime: the files' sizes differ
  options.box_size_mpc_h = 100.0;
  options.files = 7;
  options.threads = 2;
  options.chunk_particles = 4096;  // several chunks per file
  return options;
}

struct ReadBack {
  SnapshotHeader header;
  std::vector<double> positions;  // x,y,z
  std::vector<float> velocities;
  std::vector<std::uint64_t> ids;
  std::vector<double> masses;
  std::vector<std::uint8_t> types;
};

ReadBack ReadSnapshot(const std::string& base) {
  auto source = OpenSnapshot(base, ReadOptions{});
  ReadBack out;
  out.header = source->header();
  ParticleChunk chunk;
  while (source->Next(chunk)) {
    out.positions.insert(out.positions.end(), chunk.position.begin(), chunk.position.end());
    out.velocities.insert(out.velocities.end(), chunk.velocity.begin(), chunk.velocity.end());
    out.ids.insert(out.ids.end(), chunk.id.begin(), chunk.id.end());
    out.masses.insert(out.masses.end(), chunk.mass.begin(), chunk.mass.end());
    out.types.insert(out.types.end(), chunk.type.begin(), chunk.type.end());
  }
  return out;
}

// Share of the points in the densest 1% of the cells of a 32^3 grid.
double DensestCellShare(const std::vector<double>& positions, double box) {
  constexpr int kCells = 32;
  std::vector<std::uint64_t> counts(kCells * kCells * kCells, 0);
  const std::size_t n = positions.size() / 3;
  for (std::size_t i = 0; i < n; ++i) {
    int cell[3];
    for (int k = 0; k < 3; ++k) cell[k] = std::min(kCells - 1, static_cast<int>(positions[3 * i + k] / box * kCells));
    ++counts[(static_cast<std::size_t>(cell[0]) * kCells + cell[1]) * kCells + cell[2]];
  }
  std::sort(counts.begin(), counts.end(), std::greater<>());
  const std::size_t top = counts.size() / 100;
  return static_cast<double>(std::accumulate(counts.begin(), counts.begin() + static_cast<std::ptrdiff_t>(top), std::uint64_t{0})) /
         static_cast<double>(n);
}

// ---- NFW profile --------------------------------------------------------

TEST(NfwProfileTest, MassShapeSeriesJoinsTheClosedForm) {
  for (double x : {0.999e-3, 1.001e-3}) {
    const double closed = std::log1p(x) - x / (1.0 + x);
    EXPECT_NEAR(NfwMassShape(x), closed, 1e-7 * closed) << x;
  }
  EXPECT_NEAR(NfwMassShape(1.0), std::log(2.0) - 0.5, 1e-15);
  EXPECT_DOUBLE_EQ(NfwEnclosedFraction(7.0, 1.0), 1.0);
  EXPECT_DOUBLE_EQ(NfwEnclosedFraction(7.0, 0.0), 0.0);
}

TEST(NfwProfileTest, DuffyRelationAtItsPivotMass) {
  EXPECT_NEAR(DuffyConcentration(2e12), 10.14, 1e-12);
  EXPECT_LT(DuffyConcentration(1e15), DuffyConcentration(1e12));  // heavier halos are less concentrated
}

TEST(NfwProfileTest, TableInvertsTheEnclosedMass) {
  const NfwRadiusTable table;
  for (int index : {0, 17, NfwRadiusTable::kConcentrations - 1}) {
    const double c = table.Concentration(index);
    for (double u : {1e-6, 1e-3, 0.01, 0.1, 0.37, 0.5, 0.8, 0.99, 0.999999}) {
      const double q = table.Radius(index, u);
      EXPECT_NEAR(NfwEnclosedFraction(c, q), u, 2e-5) << "c = " << c << ", u = " << u;
    }
  }
  EXPECT_EQ(table.NearestIndex(1.0), 0);
  EXPECT_EQ(table.NearestIndex(1000.0), NfwRadiusTable::kConcentrations - 1);
  EXPECT_EQ(table.NearestIndex(table.Concentration(20) * 1.01), 20);
}

TEST(RandomTest, GaussianMatchesTheNormalDistribution) {
  Random random(42);
  constexpr int kSamples = 1'000'000;
  const std::vector<double> points = {-4.0, -3.7, -2.0, -1.0, -0.3, 0.0, 0.5, 1.5, 3.0, 3.7};
  std::vector<int> below(points.size(), 0);
  double sum = 0, sum2 = 0, sum4 = 0;
  for (int i = 0; i < kSamples; ++i) {
    const double g = random.Gaussian();
    ASSERT_TRUE(std::isfinite(g));
    sum += g;
    sum2 += g * g;
    sum4 += g * g * g * g;
    for (std::size_t p = 0; p < points.size(); ++p) below[p] += g < points[p];
  }
  EXPECT_NEAR(sum / kSamples, 0.0, 0.005);    // sigma of the mean: 0.001
  EXPECT_NEAR(sum2 / kSamples, 1.0, 0.007);   // sigma: 0.0014
  EXPECT_NEAR(sum4 / kSamples, 3.0, 0.05);    // sigma: 0.01
  // The CDF at each point (including beyond the ziggurat's tail start, 3.654)
  // within 5 binomial sigma.
  for (std::size_t p = 0; p < points.size(); ++p) {
    const double expected = 0.5 * std::erfc(-points[p] / std::sqrt(2.0));
    const double sigma = std::sqrt(expected * (1.0 - expected) / kSamples);
    EXPECT_NEAR(static_cast<double>(below[p]) / kSamples, expected, 5.0 * sigma + 1e-6) << "x = " << points[p];
  }
}

TEST(RandomTest, DirectionsAreUnitAndIsotropic) {
  Random random(7);
  constexpr int kSamples = 200000;
  double dir_sum[3] = {0, 0, 0}, z2 = 0;
  for (int i = 0; i < kSamples; ++i) {
    const auto d = random.Direction();
    EXPECT_NEAR(d[0] * d[0] + d[1] * d[1] + d[2] * d[2], 1.0, 1e-12);
    for (int k = 0; k < 3; ++k) dir_sum[k] += d[k];
    z2 += d[2] * d[2];
  }
  for (double s : dir_sum) EXPECT_NEAR(s / kSamples, 0.0, 0.006);  // sigma: 0.0013
  EXPECT_NEAR(z2 / kSamples, 1.0 / 3.0, 0.004);                     // <z^2> = 1/3; sigma: 0.00067
}

// ---- Whole snapshots ----------------------------------------------------

TEST(SynthScaleTest, FilesHoldEveryIdOnceInsideTheBox) {
  TempDir dir("synth-scale-test");
  const ScaleOptions options = SmallOptions(dir.path());
  const ScaleResult result = RunScaleGenerator(options);
  ASSERT_EQ(result.files.size(), 7u);

  const ReadBack snapshot = ReadSnapshot((dir.path() / "snap").string());
  EXPECT_EQ(snapshot.header.format, "gadget2");
  EXPECT_EQ(snapshot.header.files.size(), 7u);
  EXPECT_EQ(snapshot.header.total_count, options.particle_count);
  EXPECT_DOUBLE_EQ(snapshot.header.box_size, 100'000.0);  // kpc/h
  EXPECT_DOUBLE_EQ(snapshot.header.omega0, 0.3);
  ASSERT_EQ(snapshot.ids.size(), options.particle_count);
  ASSERT_EQ(snapshot.velocities.size(), 3 * options.particle_count);

  std::vector<std::uint64_t> ids = snapshot.ids;
  std::sort(ids.begin(), ids.end());
  for (std::size_t i = 0; i < ids.size(); ++i) ASSERT_EQ(ids[i], i + 1) << "IDs are not 1..N";
  for (double x : snapshot.positions) {
    ASSERT_GE(x, 0.0);
    ASSERT_LT(x, 100'000.0);
  }
  for (float v : snapshot.velocities) ASSERT_TRUE(std::isfinite(v));
  EXPECT_TRUE(std::all_of(snapshot.types.begin(), snapshot.types.end(), [](std::uint8_t t) { return t == 1; }));
  const double expected_mass = 0.3 * kCriticalDensity * 1e6 / 100'003.0;
  EXPECT_NEAR(result.particle_mass, expected_mass, 1e-12 * expected_mass);
  for (double m : snapshot.masses) ASSERT_DOUBLE_EQ(m, result.particle_mass);
}

TEST(SynthScaleTest, HeadersCountEachFileAndTheWhole) {
  TempDir dir("synth-scale-test");
  const ScaleOptions options = SmallOptions(dir.path());
  const ScaleResult result = RunScaleGenerator(options);
  std::uint64_t sum = 0;
  for (int f = 0; f < 7; ++f) {
    const fs::path path = dir.path() / ("snap." + std::to_string(f));
    ASSERT_EQ(result.files[f], path.string());
    const auto bytes = ReadFileBytes(path);
    ASSERT_GT(bytes.size(), 20u + kGadgetHeaderSize);
    ASSERT_EQ(std::string(bytes.begin() + 4, bytes.begin() + 8), "HEAD");  // format 2 block name
    const std::size_t header = 20;
    const auto npart = LoadHostOrder<std::uint32_t>(bytes, header + kHeaderNpartOffset + 4);
    EXPECT_EQ(npart, (100'003u - f + 6) / 7) << path;  // stride-7 share: 14287 or 14286
    EXPECT_EQ(LoadHostOrder<std::uint32_t>(bytes, header + kHeaderNpartOffset), 0u);  // no gas
    EXPECT_EQ(LoadHostOrder<std::uint32_t>(bytes, header + kHeaderNpartTotalOffset + 4), 100'003u);
    EXPECT_EQ(LoadHostOrder<std::uint32_t>(bytes, header + kHeaderNpartTotalHighOffset + 4), 0u);
    EXPECT_EQ(LoadHostOrder<std::int32_t>(bytes, header + kHeaderNumFilesOffset), 7);
    EXPECT_DOUBLE_EQ(LoadHostOrder<double>(bytes, header + kHeaderBoxSizeOffset), 100'000.0);
    EXPECT_DOUBLE_EQ(LoadHostOrder<double>(bytes, header + kHeaderMassOffset + 8), result.particle_mass);
    EXPECT_DOUBLE_EQ(LoadHostOrder<double>(bytes, header + kHeaderTimeOffset), 1.0);
    // HEAD, POS, VEL and 4-byte IDs, each with a 16-byte name record and two markers.
    EXPECT_EQ(bytes.size(), 4 * 24 + kGadgetHeaderSize + 28u * npart);
    sum += npart;
  }
  EXPECT_EQ(sum, 100'003u);
  EXPECT_FALSE(fs::exists(dir.path() / "snap.7"));
}

TEST(SynthScaleTest, SameSeedSameBytesWhateverTheThreadCount) {
  TempDir one("synth-scale-test"), three("synth-scale-test"), reseeded("synth-scale-test");
  ScaleOptions options = SmallOptions(one.path());
  options.threads = 1;
  RunScaleGenerator(options);
  options.output_directory = three.path().string();
  options.threads = 3;
  RunScaleGenerator(options);
  options.output_directory = reseeded.path().string();
  options.seed = 2;
  RunScaleGenerator(options);
  for (int f = 0; f < 7; ++f) {
    const std::string name = "snap." + std::to_string(f);
    const auto reference = ReadFileBytes(one.path() / name);
    EXPECT_TRUE(reference == ReadFileBytes(three.path() / name)) << name << " differs between 1 and 3 threads";
    EXPECT_FALSE(reference == ReadFileBytes(reseeded.path() / name)) << name << " ignores the seed";
  }
}

TEST(SynthScaleTest, IsolatedHaloFollowsNfw) {
  TempDir dir("synth-scale-test");
  ScaleOptions options = SmallOptions(dir.path());
  options.particle_count = 100'000;
  options.files = 2;
  options.halo_count = 1;
  options.halo_fraction = 1.0;
  options.filament_fraction = 0.0;
  options.output_unit = LengthUnit::kMpcPerH;
  RunScaleGenerator(options);
  const CosmicWeb web = BuildCosmicWeb(options);  // the same draw as the generator's
  ASSERT_EQ(web.halos.size(), 1u);
  const ScaleHalo& halo = web.halos[0];
  ASSERT_EQ(halo.count, 100'000u);
  const double c = web.nfw.Concentration(halo.concentration_index);

  const ReadBack snapshot = ReadSnapshot((dir.path() / "snap").string());
  ASSERT_EQ(snapshot.ids.size(), 100'000u);
  std::vector<double> q(snapshot.ids.size());
  for (std::size_t i = 0; i < q.size(); ++i) {
    double r2 = 0;
    for (int k = 0; k < 3; ++k) {
      double d = snapshot.positions[3 * i + k] - halo.center[k];
      d -= 100.0 * std::round(d / 100.0);  // minimal image: the halo may straddle the box edge
      r2 += d * d;
    }
    q[i] = std::sqrt(r2) / halo.r200;
  }
  std::sort(q.begin(), q.end());
  EXPECT_LE(q.back(), 1.0 + 1e-5);  // truncated at r_200 (float positions)
  // Binomial sigma of an enclosed fraction with 10^5 particles is at most
  // 0.0016; the tolerance is 4 sigma.
  for (double radius : {0.02, 0.05, 0.1, 0.2, 0.35, 0.5, 0.75}) {
    const double measured =
        static_cast<double>(std::upper_bound(q.begin(), q.end(), radius) - q.begin()) / static_cast<double>(q.size());
    EXPECT_NEAR(measured, NfwEnclosedFraction(c, radius), 0.0065) << "q = " << radius << ", c = " << c;
  }

  // Velocities: the halo's bulk velocity plus its dispersion in each axis.
  for (int k = 0; k < 3; ++k) {
    double sum = 0, sum2 = 0;
    for (std::size_t i = 0; i < snapshot.ids.size(); ++i) sum += snapshot.velocities[3 * i + k];
    const double mean = sum / 1e5;
    for (std::size_t i = 0; i < snapshot.ids.size(); ++i) {
      const double d = snapshot.velocities[3 * i + k] - mean;
      sum2 += d * d;
    }
    EXPECT_NEAR(mean, halo.bulk_velocity[k], 0.02 * halo.velocity_dispersion);
    EXPECT_NEAR(std::sqrt(sum2 / 1e5), halo.velocity_dispersion, 0.01 * halo.velocity_dispersion);
  }
}

TEST(SynthScaleTest, ClusteringIsFarAboveUniform) {
  auto densest_share = [](double halo_fraction, double filament_fraction) {
    TempDir dir("synth-scale-test");
    ScaleOptions options = SmallOptions(dir.path());
    options.particle_count = 200'000;
    options.files = 2;
    options.halo_fraction = halo_fraction;
    options.filament_fraction = filament_fraction;
    options.output_unit = LengthUnit::kMpcPerH;
    RunScaleGenerator(options);
    return DensestCellShare(ReadSnapshot((dir.path() / "snap").string()).positions, 100.0);
  };
  const double uniform = densest_share(0.0, 0.0);
  const double filaments = densest_share(0.0, 1.0);
  const double mixed = densest_share(0.5, 0.3);
  // A Poisson set with ~6 points a cell puts ~2.2% of them in the densest 1%.
  EXPECT_LT(uniform, 0.03);
  EXPECT_GT(filaments, 3.0 * uniform) << "filaments " << filaments << ", uniform " << uniform;
  EXPECT_GT(mixed, 10.0 * uniform) << "default mix " << mixed << ", uniform " << uniform;
}

TEST(SynthScaleTest, ParticlesPerFileBoundsEachFileAndFormat1Reads) {
  TempDir dir("synth-scale-test");
  ScaleOptions options = SmallOptions(dir.path());
  options.particle_count = 50'000;
  options.files = 0;
  options.particles_per_file = 12'000;  // -> 5 files of 10000
  options.format = GadgetFormat::kFormat1;
  options.snapshot_prefix = "box";
  const ScaleResult result = RunScaleGenerator(options);
  ASSERT_EQ(result.files.size(), 5u);
  const ReadBack snapshot = ReadSnapshot((dir.path() / "box").string());
  EXPECT_EQ(snapshot.header.format, "gadget1");
  EXPECT_EQ(snapshot.header.total_count, 50'000u);
  for (const auto& file : result.files) {
    const auto bytes = ReadFileBytes(file);
    EXPECT_EQ(LoadHostOrder<std::uint32_t>(bytes, 4 + kHeaderNpartOffset + 4), 10'000u) << file;
  }
}

TEST(SynthScaleTest, OneFileTakesThePrefixAsItsName) {
  TempDir dir("synth-scale-test");
  ScaleOptions options = SmallOptions(dir.path());
  options.particle_count = 1000;
  options.files = 1;
  const ScaleResult result = RunScaleGenerator(options);
  ASSERT_EQ(result.files, std::vector<std::string>{(dir.path() / "snap").string()});
  EXPECT_EQ(ReadSnapshot(result.files[0]).header.total_count, 1000u);
}

TEST(SynthScaleTest, ChunksOfBillionsOfParticlesIndexWithoutOverflow) {
  // 6e9 particles (IDs beyond 2^32) in 50 files, drawn in memory: the last
  // chunk of the last file ends at ID N.
  ScaleOptions options;
  options.particle_count = 6'000'000'000;
  options.files = 50;
  options.halo_count = 1000;
  options.node_count = 64;
  ValidateScaleOptions(options);
  const CosmicWeb web = BuildCosmicWeb(options);
  EXPECT_EQ(web.halo_particles + web.filament_particles + web.background_particles, options.particle_count);
  const ScaleSampler sampler(web, options.seed, 50, options.chunk_particles, 1.0);
  EXPECT_EQ(sampler.FileParticleCount(49), 120'000'000u);
  for (int file : {0, 17, 49}) {
    const std::uint64_t last_chunk = sampler.ChunkCount(file) - 1;
    for (std::uint64_t chunk : {std::uint64_t{0}, last_chunk / 2, last_chunk}) {
      ScaleChunk out;
      sampler.Fill(file, chunk, out);
      ASSERT_FALSE(out.ids.empty());
      for (std::size_t i = 0; i < out.ids.size(); ++i) {
        ASSERT_EQ((out.ids[i] - 1) % 50, static_cast<std::uint64_t>(file));
        if (i > 0) {
          ASSERT_EQ(out.ids[i], out.ids[i - 1] + 50);
        }
      }
      for (float x : out.positions) {
        ASSERT_GE(x, 0.0f);
        ASSERT_LT(x, 500.0f);
      }
      if (file == 49 && chunk == last_chunk) {
        EXPECT_EQ(out.ids.back(), options.particle_count);
      }
    }
  }
}

TEST(SynthScaleTest, RejectsImpossibleOptions) {
  TempDir dir("synth-scale-test");
  auto expect_invalid = [&](const std::function<void(ScaleOptions&)>& change) {
    ScaleOptions options = SmallOptions(dir.path());
    change(options);
    try {
      RunScaleGenerator(options);
      ADD_FAILURE() << "accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument) << e.what();
    }
  };
  expect_invalid([](ScaleOptions& o) { o.halo_fraction = 0.8; });  // + 0.3 filaments > 1
  expect_invalid([](ScaleOptions& o) { o.particle_count = 0; });
  expect_invalid([](ScaleOptions& o) { o.particle_count = 5; });  // 7 files
  expect_invalid([](ScaleOptions& o) { o.particles_per_file = 10; });  // and files = 7
  expect_invalid([](ScaleOptions& o) {  // 10^7 files of one particle
    o.files = 0;
    o.particle_count = 10'000'000;
    o.particles_per_file = 1;
  });
  expect_invalid([](ScaleOptions& o) { o.box_size_mpc_h = -1; });
  expect_invalid([](ScaleOptions& o) { o.node_count = 1; });
  expect_invalid([](ScaleOptions& o) {
    o.files = 1;
    o.particle_count = kMaxScaleParticlesPerFile + 1;
  });
  EXPECT_TRUE(fs::is_empty(dir.path()));
}

TEST(SynthScaleTest, UnwritableDirectoryIsAnIoErrorAndLeavesNoFiles) {
  TempDir dir("synth-scale-test");
  const fs::path blocker = dir.path() / "not_a_directory";
  std::ofstream(blocker) << "x";
  ScaleOptions options = SmallOptions(blocker / "out");
  try {
    RunScaleGenerator(options);
    ADD_FAILURE() << "accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kIo) << e.what();
    EXPECT_NE(std::string(e.what()).find("not_a_directory"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace octocosm::synth
