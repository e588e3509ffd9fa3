// octocosm-bench-accuracy: how faithful octocosm's levels of detail are,
// measured against the Point Cloud Library (the tables of
// docs/ACCURACY.md come from this program).
//
// Data sets:
//   synth   clustered points from the scale generator (octocosm synth scale:
//           NFW halos on a filament skeleton plus a background, one particle
//           mass) in a periodic box of 512 Mpc/h, written in Mpc/h so that
//           the box is dyadic (PCL's float voxels are then octocosm's cells)
//   shared  the real snapshots in ../shared/data when present: the GADGET-2
//           galaxy IC, the LCDM gas IC at z = 10, the two-file format-2 run at
//           z = 2.6, the GADGET-4 galaxy collision at t = 10 (each with two or
//           three particle species of different masses), on dyadic cubes
//           that hold them, at capacity 1000 so that they have several levels
// For each data set, ingested with `octocosm ingest`'s code path at
// alpha 0, 0.5 and 1:
//   keys      every particle's leaf in the store (alpha 0.5, the cube ingest
//             chooses) against its leaf in PCL's adaptive octree
//             (OctreePointCloudPointVector, dynamic depth = capacity): the
//             number that differ, which must be 0
//   coverage  per level, on the voxels of level L + b (8^b >= capacity): the
//             fraction of occupied voxels (pcl::VoxelGrid on the full data)
//             holding a point of the level, the same among sparse voxels
//             (fewer than n / m points), and the fraction of the mass lying
//             in voxels the level dropped; octocosm at each alpha next to
//             pcl::RandomSample with as many points as the level
//   density   per level and sampler, the relative error of each voxel's mass
//             estimate (estimate / true - 1): mean +- standard error, median,
//             5th and 95th percentiles, for sparse and dense voxels
// Then the stress figures:
//   quantization  the worst position error through EncodeBlock/DecodeBlock at
//             every depth 0..21, in units of the documented bound s / 131072
//   offsets   the worst position error of every particle in its leaf for
//             boxes 1e-3 to 1e7 wide at offsets 0, 1e6 and 1e9 (BuildSubtree,
//             EncodeBlock, DecodeBlock), against s / 131072 and the box
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "accuracy/level_comparison.h"
#include "accuracy/level_samples.h"
#include "accuracy/pcl_octree_leaves.h"
#include "accuracy/position_errors.h"
#include "accuracy/snapshot_points.h"
#include "base/error.h"
#include "index/dataset.h"
#include "ingest/ingest.h"
#include "synth/scale_generator.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using namespace accuracy;

struct DataSet {
  std::string name;
  std::string input;          // a snapshot OpenSnapshot reads
  std::optional<Cube> cube;   // a dyadic cube holding the data, when ingest's own is not dyadic
};

struct Settings {
  std::string dir;
  std::size_t capacity = 16000;
  std::vector<double> alphas = {0.0, 0.5, 1.0};
};

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// Ingests `input` into a fresh store under the scratch directory and reads it back.
LevelSamples IngestLevels(const DataSet& data, const ParticleChunk& points, const Settings& settings, double alpha,
                          const std::optional<Cube>& cube, Cube& used) {
  IngestOptions o;
  o.inputs = {data.input};
  o.output = (fs::path(settings.dir) / "store").string();
  o.temp_dir = settings.dir;
  o.quiet = true;
  o.tree.capacity = settings.capacity;
  o.tree.sampler.alpha = alpha;
  o.tree.coarse = CoarsePoints::kSample;  // PCL's random sample checks the subselection
  o.cube = cube;
  fs::remove_all(o.output);
  Ingest(o);
  const Dataset dataset = Dataset::Open(o.output);
  used = dataset.cube(0);
  LevelSamples levels(points.id);
  levels.AddStore(dataset, 0);
  fs::remove_all(o.output);
  return levels;
}

void PrintCoverage(const std::vector<LevelComparison>& levels, const std::vector<double>& alphas) {
  std::printf("\ncoverage: voxels kept (holding a point of the level), sparse voxels kept, mass in dropped voxels\n");
  std::printf("%5s %4s %9s %9s %9s |", "level", "bits", "points", "voxels", "sparse");
  for (const char* what : {"kept", "sparse kept", "mass dropped"}) {
    std::printf(" %-*s|", static_cast<int>(7 * (alphas.size() + 1)), what);
  }
  std::printf("\n%5s %4s %9s %9s %9s |", "", "", "", "", "");
  for (int k = 0; k < 3; ++k) {
    for (const double a : alphas) std::printf(" a=%-4.1f", a);
    std::printf(" %6s|", "random");
  }
  std::printf("\n");
  for (const LevelComparison& l : levels) {
    const SampleScore& first = l.random;
    std::printf("%5d %4d %9zu %9zu %9zu |", l.level, l.voxel_bits, first.points, l.voxels, first.sparse_voxels);
    for (int k = 0; k < 3; ++k) {
      const auto value = [k](const SampleScore& s) {
        return k == 0 ? s.voxels_kept : k == 1 ? s.sparse_voxels_kept : s.mass_dropped;
      };
      for (const SampleScore& s : l.octocosm) std::printf(" %6.3f", value(s));
      std::printf(" %6.3f|", value(l.random));
    }
    std::printf("\n");
  }
}

void PrintDensity(const std::vector<LevelComparison>& levels, const std::vector<double>& alphas) {
  std::printf("\ndensity: relative error of each voxel's mass estimate (estimate / true - 1)\n");
  std::printf("%5s %-9s | %-46s | %-46s\n", "level", "sampler", "sparse voxels", "dense voxels");
  std::printf("%5s %-9s |", "", "");
  for (int g = 0; g < 2; ++g) std::printf(" %7s %15s %7s %7s %7s |", "voxels", "mean +- se", "median", "p05", "p95");
  std::printf("\n");
  for (const LevelComparison& l : levels) {
    for (std::size_t k = 0; k <= l.octocosm.size(); ++k) {
      const SampleScore& s = k < l.octocosm.size() ? l.octocosm[k] : l.random;
      char name[16];
      if (k < alphas.size()) {
        std::snprintf(name, sizeof name, "a=%.1f", alphas[k]);
      } else {
        std::snprintf(name, sizeof name, "random");
      }
      std::printf("%5d %-9s |", l.level, name);
      for (const ErrorDistribution* d : {&s.sparse, &s.dense}) {
        std::printf(" %7zu %+7.3f+-%-6.3f %+7.3f %+7.3f %+7.3f |", d->voxels, d->mean, d->standard_error, d->median,
                    d->p05, d->p95);
      }
      std::printf("\n");
    }
  }
}

void RunDataSet(const DataSet& data, const Settings& settings) {
  const auto start = std::chrono::steady_clock::now();
  const ParticleChunk points = ReadSnapshotPoints(data.input);
  std::vector<LevelSamples> trees;
  Cube own, used;
  // Keys: on the cube ingest chooses by itself.
  const LevelSamples keys_tree = IngestLevels(data, points, settings, 0.5, std::nullopt, own);
  const std::vector<NodeKey> octocosm = keys_tree.Leaves();
  const std::vector<NodeKey> pcl = PclOctreeLeaves(points.position, own, settings.capacity, kMaxLevel);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < octocosm.size(); ++i) differ += octocosm[i] != pcl[i];
  // Levels: at every alpha, on a dyadic cube.
  for (const double alpha : settings.alphas) trees.push_back(IngestLevels(data, points, settings, alpha, data.cube, used));
  // The random sample takes the level sizes of the first tree; they are the
  // same at every alpha (the tree's shape does not depend on it).
  const std::vector<LevelComparison> levels = CompareLevels(points, trees, used, settings.capacity, 17);
  std::size_t disagreements = 0;
  for (const LevelComparison& l : levels) disagreements += l.disagreements;

  std::printf("\n== %s: %zu particles, cube origin (%g, %g, %g) size %g%s, capacity %zu, depth %d ==\n",
              data.name.c_str(), points.size(), own.origin[0], own.origin[1], own.origin[2], own.size,
              own.periodic ? " (periodic)" : "", settings.capacity, keys_tree.depth());
  std::printf("keys: %zu of %zu particles in a different leaf than PCL's adaptive octree (capacity %zu, depth 21)\n",
              differ, points.size(), settings.capacity);
  if (data.cube) {
    std::printf("levels on the dyadic cube origin (%g, %g, %g) size %g; ", used.origin[0], used.origin[1],
                used.origin[2], used.size);
  }
  std::printf("voxels where pcl::VoxelGrid and octocosm disagree: %zu\n", disagreements);
  PrintCoverage(levels, settings.alphas);
  PrintDensity(levels, settings.alphas);
  std::printf("(%s: %.1f s)\n", data.name.c_str(), Seconds(start));
  std::fflush(stdout);
}

void PrintQuantization() {
  std::printf("\n== quantization: worst position error through EncodeBlock/DecodeBlock, 4000 random points a node ==\n");
  std::printf("%5s %12s %12s | %-28s | %-28s\n", "depth", "s / size", "s / 131072", "cube [0, 1)", "cube 1e6 + [0, 1000)");
  std::printf("%5s %12s %12s | %13s %14s | %13s %14s\n", "", "", "(unit cube)", "worst", "worst/bound", "worst",
              "worst/bound");
  const Cube unit{{0, 0, 0}, 1, false}, far{{1e6, 1e6, 1e6}, 1000, false};
  for (int level = 0; level <= kMaxLevel; ++level) {
    const PositionErrors a = NodePositionErrors(unit, level, 4000, 100 + level);
    const PositionErrors b = NodePositionErrors(far, level, 4000, 200 + level);
    std::printf("%5d %12.4g %12.4g | %13.4g %14.6f | %13.4g %14.6f\n", level, std::ldexp(1.0, -level),
                unit.NodeSize(level) / 131072, a.worst, a.worst_over_bound, b.worst, b.worst_over_bound);
  }
}

void PrintOffsets(std::size_t capacity) {
  std::printf("\n== offsets: 100000 clustered points in a box, every particle's worst error in its leaf ==\n");
  std::printf("%8s %8s %6s %12s %12s %14s %12s\n", "offset", "width", "depth", "ulp(offset)", "worst", "worst/bound",
              "worst/width");
  std::mt19937_64 rng(3);
  for (const double offset : {0.0, 1e6, 1e9}) {
    for (const double width : {1e-3, 1.0, 1e3, 1e7}) {
      ParticleChunk points;
      std::uniform_real_distribution<double> unit(0, 1);
      std::normal_distribution<double> gauss(0, 0.01);
      for (std::size_t i = 0; i < 100000; ++i) {
        const double centre = 0.2 + 0.15 * static_cast<double>(i % 5);
        for (int a = 0; a < 3; ++a) {
          const double t = i % 3 == 0 ? unit(rng) : std::clamp(centre + gauss(rng), 0.0, 0.999);
          points.position.push_back(offset + width * t);
        }
        points.mass.push_back(1);
        points.type.push_back(0);
        points.id.push_back(i);
      }
      std::array<double, 3> lo{offset, offset, offset}, hi{offset + width, offset + width, offset + width};
      const Cube cube = Cube::FromBounds(lo, hi);
      SubtreeOptions options;
      options.capacity = capacity;
      const PositionErrors errors = LeafPositionErrors(points, cube, options);
      const double ulp = std::nextafter(offset + width, INFINITY) - (offset + width);
      std::printf("%8g %8g %6d %12.3g %12.3g %14.6f %12.3g\n", offset, width, errors.depth, ulp, errors.worst,
                  errors.worst_over_bound, errors.worst / width);
    }
  }
}

}  // namespace
}  // namespace octocosm

int main(int argc, char** argv) {
  using namespace octocosm;
  Settings settings;
  settings.dir = "octocosm-accuracy-bench";
  double points = 4e6;
  std::string shared = OCTOCOSM_SHARED_DATA;
  bool no_synth = false, no_stress = false;
  CLI::App app{
      "octocosm-bench-accuracy: octocosm's octree and levels of detail against the Point Cloud Library.\n"
      "For generated clustered data (synth scale) and the real snapshots in the shared data folder, ingested at\n"
      "alpha 0, 0.5 and 1: each particle's leaf key against PCL's adaptive octree; per level, the voxels kept\n"
      "and the mass dropped, next to pcl::RandomSample with as many points (occupied voxels from\n"
      "pcl::VoxelGrid); the distribution of the relative error of each voxel's mass estimate, sparse and dense\n"
      "voxels apart. Then the quantization error at every depth and the position error at large offsets.\n"
      "docs/ACCURACY.md explains every column."};
  app.add_option("--dir", settings.dir, "scratch directory (removed afterwards)")->default_val(settings.dir);
  app.add_option("--points", points, "particles in the generated snapshot")->default_val(points);
  app.add_option("--capacity", settings.capacity, "most points per node")->default_val(settings.capacity);
  app.add_option("--alpha", settings.alphas, "density exponents of the sampler to compare")->default_val(settings.alphas);
  app.add_option("--shared-data", shared, "the shared snapshots folder (skipped when absent)")->default_val(shared);
  app.add_flag("--no-synth", no_synth, "skip the generated data set");
  app.add_flag("--no-stress", no_stress, "skip the quantization and offset figures");
  CLI11_PARSE(app, argc, argv);

  try {
    const auto start = std::chrono::steady_clock::now();
    fs::remove_all(settings.dir);
    fs::create_directories(settings.dir);
    std::vector<DataSet> sets;
    if (!no_synth) {
      synth::ScaleOptions scale;
      scale.output_directory = (fs::path(settings.dir) / "synth").string();
      scale.particle_count = static_cast<std::uint64_t>(points);
      scale.box_size_mpc_h = 512;
      scale.output_unit = synth::LengthUnit::kMpcPerH;
      scale.seed = 7;
      synth::RunScaleGenerator(scale, nullptr);
      sets.push_back({"synth scale, 512 Mpc/h periodic box", (fs::path(scale.output_directory) / "snap").string(),
                      std::nullopt});
    }
    if (fs::is_directory(shared)) {
      const auto at = [&](const char* path) { return (fs::path(shared) / path).string(); };
      sets.push_back({"GADGET-2 galaxy IC", at("gadget2_ics/galaxy_littleendian.dat"),
                      Cube{{-256, -256, -256}, 512, false}});
      sets.push_back({"GADGET-2 LCDM gas IC, z = 10", at("gadget2_ics/lcdm_gas_littleendian.dat"),
                      Cube{{0, 0, 0}, 65536, false}});
      sets.push_back({"GADGET-2 format 2, two files, z = 2.6", at("gadget2_format2_multifile/test_g2_snap"),
                      Cube{{0, 0, 0}, 4096, false}});
      sets.push_back({"GADGET-4 galaxy collision, t = 10",
                      at("gadget4_hdf5_galaxy_collision_timeseries/snapshot_020.hdf5"),
                      Cube{{-2048, -2048, -2048}, 4096, false}});
    } else {
      std::printf("(no shared data at %s: real snapshots skipped)\n", shared.c_str());
    }
    std::printf("octocosm-bench-accuracy: capacity %zu\n", settings.capacity);
    for (const DataSet& data : sets) {
      // The real snapshots are small: a capacity that gives them several levels.
      Settings own = settings;
      if (data.cube) own.capacity = std::min<std::size_t>(settings.capacity, 1000);
      RunDataSet(data, own);
    }
    if (!no_stress) {
      PrintQuantization();
      PrintOffsets(settings.capacity / 16);
    }
    fs::remove_all(settings.dir);
    std::printf("\ntotal %.1f s\n", Seconds(start));
  } catch (const Error& e) {
    std::fprintf(stderr, "octocosm-bench-accuracy: %s\n", e.what());
    return 1;
  }
  return 0;
}
