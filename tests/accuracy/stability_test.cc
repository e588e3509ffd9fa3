// The numerical stability suite (docs/ACCURACY.md): the inputs
// that break numerical code, end to end through the real code paths (Ingest,
// BuildSubtree, EncodeBlock / DecodeBlock). Each test states the bound it
// asserts. Cases that are also tests of their own modules (faces and the upper
// edge in index/cube, coincident points in the subtree builder, NaN per reader,
// random periodic steps in ingest) are listed in docs/ACCURACY.md next to
// these; the tests here push them further or through the whole pipeline.
//
// Notation: s is the edge of the node holding a point, M the largest
// coordinate magnitude in the cube (|origin| + size), ulp(M) the spacing of
// doubles there. Neither the input nor a decoded position can be finer than
// an ulp, so position bounds are the documented quantization bound s / 131072
// plus a few ulps of M.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <unordered_map>
#include <vector>

#include "accuracy/position_errors.h"
#include "base/error.h"
#include "index/block_codec.h"
#include "index/dataset.h"
#include "index/subtree_builder.h"
#include "tests/ingest/ingest_fixture.h"
#include "tests/ingest/store_check.h"
#include "ingest/ingest.h"
#include "synth/gadget_writer.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using namespace testing_support;

struct Particle {
  double x[3];
  double mass = 1;
  std::uint64_t id = 0;
  float v[3] = {0, 0, 0};
};

enum class Width { kFloat32, kFloat64 };

// Raw binary records x, y, z, vx, vy, vz, mass (all float32 or all float64),
// id u64; returns the layout to read them with.
std::string WriteRaw(const fs::path& path, const std::vector<Particle>& particles, Width width) {
  std::ofstream out(path, std::ios::binary);
  const auto put = [&](double value) {
    if (width == Width::kFloat32) {
      const auto f = static_cast<float>(value);
      out.write(reinterpret_cast<const char*>(&f), sizeof f);
    } else {
      out.write(reinterpret_cast<const char*>(&value), sizeof value);
    }
  };
  for (const Particle& p : particles) {
    for (const double x : p.x) put(x);
    for (const float v : p.v) put(v);
    put(p.mass);
    out.write(reinterpret_cast<const char*>(&p.id), sizeof p.id);
  }
  return width == Width::kFloat32 ? "xyz:f32,vel:f32,mass:f32,id:u64" : "xyz:f64,vel:f64,mass:f64,id:u64";
}

double Ulp(double x) { return std::nextafter(std::fabs(x), INFINITY) - std::fabs(x); }

// Gaussian clumps on a background inside [offset, offset + width)^3.
std::vector<Particle> ClumpsInBox(std::size_t n, double offset, double width, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  std::normal_distribution<double> gauss(0, 0.01);
  std::vector<Particle> particles(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double centre = 0.2 + 0.15 * static_cast<double>(i % 5);
    for (double& x : particles[i].x) {
      const double t = i % 3 == 0 ? unit(rng) : std::clamp(centre + gauss(rng), 0.0, 0.999);
      x = std::min(offset + width * t, std::nextafter(offset + width, -INFINITY));
    }
    particles[i].mass = 1 + static_cast<double>(i % 4);
    particles[i].id = 7 + 3 * i;
  }
  return particles;
}

class Stability : public IngestFixture {
 protected:
  // Ingests one epoch of `particles` (raw, in `width`), capacity `capacity`.
  IngestOptions Ingested(const std::vector<Particle>& particles, Width width, const std::string& name,
                         std::size_t capacity, double box = -1) {
    IngestOptions o = Options({}, name);
    o.read.format = "raw";
    o.read.raw = RawLayout::Parse(WriteRaw(dir_ / (name + ".raw"), particles, width));
    o.inputs = {(dir_ / (name + ".raw")).string()};
    o.read.box_size_override = box;
    o.tree.capacity = capacity;
    Ingest(o);
    return o;
  }
};

// ---- Large offsets and box widths ---------------------------------------

struct OffsetCase {
  double offset, width;
};

class LargeOffsets : public Stability, public ::testing::WithParamInterface<OffsetCase> {};

// Boxes 1e-3 to 1e7 wide, a million to a billion units from the origin, as
// float64 input. Bound: every particle in exactly one leaf, each coordinate
// within s / 131072 + 4 ulp(M) of its input, the root's mass equal to the
// input's to 1e-12, and a tree at least 3 levels deep (the box is resolved,
// not lost to the offset). At 1e9 a double is 1.2e-7 wide, so a 1e-3 box holds
// only ~8400 distinct coordinates per axis; the ulp term then dominates.
TEST_P(LargeOffsets, PositionsWithinAHalfQuantumPlusFourUlps) {
  const auto [offset, width] = GetParam();
  const auto particles = ClumpsInBox(4000, offset, width, 11);
  const IngestOptions o = Ingested(particles, Width::kFloat64, "store", 100);
  const Dataset dataset = Dataset::Open(o.output);
  const TreeCheck check = CheckTree(dataset, 0);
  ASSERT_EQ(check.leaf_points.size(), particles.size());
  const Cube& cube = dataset.cube(0);
  const double ulps = 4 * Ulp(std::fabs(cube.origin[0]) + cube.size);
  int depth = 0;
  double total = 0, worst = 0;
  for (const Particle& p : particles) {
    total += p.mass;
    const LeafPoint& leaf = check.leaf_points.at(p.id);
    depth = std::max(depth, leaf.leaf.level());
    const double bound = cube.NodeSize(leaf.leaf.level()) / 131072 + ulps;
    for (int a = 0; a < 3; ++a) {
      const double error = std::fabs(leaf.x[a] - p.x[a]);
      worst = std::max(worst, error / bound);
      ASSERT_LE(error, bound) << "ID " << p.id << " axis " << a << " at " << p.x[a];
    }
  }
  EXPECT_GE(depth, 3);
  EXPECT_NEAR(dataset.store().dataset()["epochs"][0]["mass"].get<double>(), total, 1e-12 * total);
  RecordProperty("worst_error_over_bound", std::to_string(worst));
}

INSTANTIATE_TEST_SUITE_P(
    OffsetsAndWidths, LargeOffsets,
    ::testing::Values(OffsetCase{0, 1e-3}, OffsetCase{0, 1e7}, OffsetCase{1e6, 1e-3}, OffsetCase{1e6, 1},
                      OffsetCase{1e6, 1e3}, OffsetCase{1e6, 1e7}, OffsetCase{-1e9, 1e-3}, OffsetCase{1e9, 1e-3},
                      OffsetCase{1e9, 1}, OffsetCase{1e9, 1e3}, OffsetCase{1e9, 1e7}),
    [](const ::testing::TestParamInfo<OffsetCase>& param) {
      const auto name = [](double v) {
        if (v == 0) return std::string("0");
        std::string s = (v < 0 ? "Minus1e" : "1e") + std::to_string(static_cast<int>(std::lround(std::log10(std::fabs(v)))));
        for (char& c : s) c = c == '-' ? 'm' : c;
        return s;
      };
      return "Offset" + name(param.param.offset) + "Width" + name(param.param.width);
    });

// ---- Quantization at every depth ------------------------------------------

// The documented bound (docs/FORMAT.md §4): a decoded position is within
// s / 131072 of the original per axis, s = size / 2^L. Here at every depth 0
// to 21 through EncodeBlock / DecodeBlock, with 2000 random points a node,
// in a unit cube and in a 1000-wide cube a million units out. Bound: error
// <= s / 131072 + 4 ulp(M), and the bound is the real figure, not slack: the
// worst error reaches 95% of it at every depth. (BlockCodec.
// PositionErrorIsAtMostHalfAQuantumAtEveryDepth checks the upper bound for
// other cubes, faces included.)
TEST(StabilityQuantization, ErrorAtEveryDepthIsTheDocumentedHalfQuantum) {
  for (const Cube& cube : {Cube{{0, 0, 0}, 1, false}, Cube{{1e6, -1e6, 1e6}, 1000, false}}) {
    const double ulps = 4 * Ulp(std::fabs(cube.origin[0]) + cube.size);
    for (int level = 0; level <= kMaxLevel; ++level) {
      const accuracy::PositionErrors errors = accuracy::NodePositionErrors(cube, level, 2000, 5 + level);
      const double half_quantum = cube.NodeSize(level) / 131072;
      EXPECT_LE(errors.worst, half_quantum + ulps) << "level " << level << " cube size " << cube.size;
      EXPECT_GE(errors.worst, 0.95 * half_quantum) << "level " << level << " cube size " << cube.size;
    }
  }
}

// ---- Faces, the upper edge, float32 and float64 ---------------------------

// Points exactly on the cube's lower faces, on cell faces of levels 1-6, and
// on its upper edge x == origin + size, in float32 and float64 input (the
// same values). Bound: float32 and float64 input give byte-identical stores;
// every point is within s / 131072 of its input (in a periodic box, of its
// wrapped input); a point on a cell face is in the cell above the face; a
// point on the upper edge is in the last cell of a cube given explicitly (the
// documented clamp) and in the first cell of a periodic box (it wraps to 0).
TEST_F(Stability, FacesAndUpperEdgeInFloat32AndFloat64) {
  const double size = 64;
  std::vector<Particle> particles = ClumpsInBox(3000, 0, size, 3);
  for (Particle& p : particles) {
    for (double& x : p.x) x = static_cast<float>(x);  // the same values in both widths
  }
  std::uint64_t id = 1000000;
  std::vector<std::uint64_t> upper_edge;
  std::mt19937_64 rng(3);
  for (int level = 1; level <= 6; ++level) {
    for (int i = 0; i < 50; ++i) {
      Particle p;
      for (double& x : p.x) x = std::ldexp(size * static_cast<double>(rng() % (1u << level)), -level);  // on faces
      p.id = id++;
      particles.push_back(p);
    }
  }
  for (int i = 0; i < 20; ++i) {
    Particle p;
    p.x[0] = size;  // the upper edge on x; y and z on faces or inside
    p.x[1] = i % 2 == 0 ? size : size / 4;
    p.x[2] = 0;
    p.id = id++;
    upper_edge.push_back(p.id);
    particles.push_back(p);
  }
  for (const bool periodic : {false, true}) {
    SCOPED_TRACE(periodic ? "periodic box" : "explicit cube");
    std::string names[2];
    for (const Width width : {Width::kFloat32, Width::kFloat64}) {
      const std::string name = std::string(periodic ? "box" : "cube") + (width == Width::kFloat32 ? "32" : "64");
      IngestOptions o = Options({}, name);
      o.read.format = "raw";
      o.read.raw = RawLayout::Parse(WriteRaw(dir_ / (name + ".raw"), particles, width));
      o.inputs = {(dir_ / (name + ".raw")).string()};
      o.tree.capacity = 60;
      if (periodic) {
        o.read.box_size_override = size;
      } else {
        o.cube = Cube{{0, 0, 0}, size, false};
      }
      Ingest(o);
      names[width == Width::kFloat32 ? 0 : 1] = o.output;
    }
    const Dataset dataset = Dataset::Open(names[1]);
    const TreeCheck f32 = CheckTree(Dataset::Open(names[0]), 0);
    const TreeCheck f64 = CheckTree(dataset, 0);
    EXPECT_EQ(FirstDifference(f32, f64), "") << "float32 and float64 input of the same values";
    const Cube& cube = dataset.cube(0);
    ASSERT_EQ(cube.periodic, periodic);
    int face_points_in_deep_leaves = 0;
    for (const Particle& p : particles) {
      const LeafPoint& leaf = f64.leaf_points.at(p.id);
      const double bound = cube.NodeSize(leaf.leaf.level()) / 131072 * (1 + 1e-12);
      for (int a = 0; a < 3; ++a) {
        double error = leaf.x[a] - p.x[a];
        if (periodic) error -= size * std::nearbyint(error / size);
        ASSERT_LE(std::fabs(error), bound) << "ID " << p.id << " axis " << a;
      }
      ASSERT_TRUE(cube.Holds(leaf.leaf, p.x)) << "ID " << p.id << " is not in the leaf its coordinates name";
      if (p.id >= 1000000 && leaf.leaf.level() >= 1) ++face_points_in_deep_leaves;
    }
    EXPECT_GT(face_points_in_deep_leaves, 100);
    for (const std::uint64_t edge : upper_edge) {
      const NodeKey leaf = f64.leaf_points.at(edge).leaf;
      const std::uint32_t last = (1u << leaf.level()) - 1;
      EXPECT_EQ(leaf.cell().x, periodic ? 0u : last) << "ID " << edge;
    }
  }
}

// ---- Coincident points and the depth limit --------------------------------

// 10^6 particles at one position (BuildSubtree and the block codec; the
// ingest test below goes through the chunker). Bound: one chain of 22 nodes
// down to level 21; the leaf holds all 10^6, every inner node exactly
// `capacity`; every node's weights sum to the 10^6 particles' mass to 1e-12;
// the leaf decodes every position within s / 131072 + 4 ulp(M) and every
// weight within one weight unit (the node's mass / (2^32 - 2^20), here 2.3e-4
// of a particle's own mass: with 10^6 points in a block the 32-bit weight
// units are shared out thinly).
TEST(StabilityDepthLimit, MillionCoincidentPointsEndInOneLeafAtLevel21) {
  const Cube cube{{-50, -50, -50}, 100, false};
  const std::size_t n = 1000000;
  ParticleChunk input;
  input.position.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    input.position.insert(input.position.end(), {12.345678, -6.789012, 0.000123});
    input.mass.push_back(1.0 + static_cast<double>(i % 7));
    input.type.push_back(static_cast<std::uint8_t>(i % 2));
    input.id.push_back(5 * i + 1);
  }
  long double mass = 0;
  for (const double m : input.mass) mass += m;
  SubtreeOptions options;
  options.capacity = 16000;
  std::vector<std::pair<NodeKey, std::size_t>> nodes;
  NodePoints leaf;
  NodeKey leaf_key;
  BuildSubtree(input, NodeKey::Root(), cube, options, [&](NodeKey key, const NodePoints& points) {
    long double sum = 0;
    for (const double w : points.weight) sum += w;
    EXPECT_NEAR(static_cast<double>(sum / mass), 1.0, 1e-12) << key.Path();
    nodes.emplace_back(key, points.size());
    if (key.level() == kMaxLevel) {
      leaf = points;
      leaf_key = key;
    }
  });
  ASSERT_EQ(nodes.size(), static_cast<std::size_t>(kMaxLevel + 1));
  // Coincident points cannot be told apart: every inner node holds one
  // cluster per particle type (two) with all their mass.
  for (const auto& [key, count] : nodes) EXPECT_EQ(count, key.level() == kMaxLevel ? n : 2u);
  ASSERT_EQ(leaf.size(), n);
  const double position[3] = {12.345678, -6.789012, 0.000123};
  const NodePoints decoded = DecodeBlock(EncodeBlock(leaf, leaf_key, cube), kAllColumns, leaf_key, cube, "leaf").points;
  double worst_position = 0, worst_weight = 0;
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) worst_position = std::max(worst_position, std::fabs(decoded.position[3 * i + a] - position[a]));
    worst_weight = std::max(worst_weight, std::fabs(decoded.weight[i] - leaf.weight[i]));
  }
  EXPECT_LE(worst_position, cube.NodeSize(kMaxLevel) / 131072 + 4 * Ulp(150));
  EXPECT_LE(worst_weight, static_cast<double>(mass) / static_cast<double>(kWeightTotalUnits) * (1 + 1e-9));
}

// Trees at the depth limit through the whole pipeline: 20000 particles within
// one level-21 cell (distinct positions 2^-32 of the cube apart, which only
// the 16 bits inside a level-21 node can tell apart) plus 20000 spread
// particles, chunked small so that the chunker must split down to the limit,
// and a second store with the limit set to 3. Bound: the dense cell ends in
// one leaf at level 21 (and the limit-3 store has leaves over capacity only at
// level 3); every position is within s / 131072 + 4 ulp(M) of its input.
TEST_F(Stability, TreesAtTheDepthLimit) {
  std::vector<Particle> particles = ClumpsInBox(20000, 0, 1, 8);
  const double cell = std::ldexp(1.0, -21);
  std::mt19937_64 rng(8);
  for (int i = 0; i < 20000; ++i) {
    Particle p;
    for (int a = 0; a < 3; ++a) p.x[a] = 0.5 + cell * (0.25 + 0.5 * std::ldexp(static_cast<double>(rng() % 1024), -10));
    p.id = 1000000 + static_cast<std::uint64_t>(i);
    particles.push_back(p);
  }
  IngestOptions o = Options({}, "deep");
  o.read.format = "raw";
  o.read.raw = RawLayout::Parse(WriteRaw(dir_ / "deep.raw", particles, Width::kFloat64));
  o.inputs = {(dir_ / "deep.raw").string()};
  o.tree.capacity = 500;
  o.max_chunk_points = 3000;
  o.cube = Cube{{0, 0, 0}, 1, false};
  Ingest(o);
  IngestOptions shallow = o;
  shallow.output = (dir_ / "shallow").string();
  shallow.tree.max_level = 3;
  Ingest(shallow);
  for (const IngestOptions* options : {&o, &shallow}) {
    const int limit = options->tree.max_level;
    SCOPED_TRACE("depth limit " + std::to_string(limit));
    const Dataset dataset = Dataset::Open(options->output);
    const TreeCheck check = CheckTree(dataset, 0);
    ASSERT_EQ(check.leaf_points.size(), particles.size());
    std::unordered_map<std::uint64_t, std::size_t> leaf_sizes;
    for (const auto& [id, leaf] : check.leaf_points) ++leaf_sizes[leaf.leaf.value()];
    std::size_t over_capacity = 0;
    for (const auto& [key, count] : leaf_sizes) {
      if (count > options->tree.capacity) {
        ++over_capacity;
        EXPECT_EQ(NodeKey::FromValue(key).level(), limit);
      }
    }
    EXPECT_GT(over_capacity, 0u);
    const NodeKey dense = check.leaf_points.at(1000000).leaf;
    EXPECT_EQ(dense.level(), limit);
    if (limit == kMaxLevel) {
      EXPECT_EQ(leaf_sizes.at(dense.value()), 20000u);
    }
    const double ulps = 4 * Ulp(1.0);
    for (const Particle& p : particles) {
      const LeafPoint& leaf = check.leaf_points.at(p.id);
      const double bound = dataset.cube(0).NodeSize(leaf.leaf.level()) / 131072 + ulps;
      for (int a = 0; a < 3; ++a) ASSERT_LE(std::fabs(leaf.x[a] - p.x[a]), bound) << "ID " << p.id;
    }
  }
}

// ---- Non-finite input ------------------------------------------------------

// NaN, +Inf and -Inf in a coordinate, a velocity or a mass, in raw float32,
// raw float64, CSV and GADGET input, through Ingest. Bound: Error::BadInput
// (exit status 4) whose message names the input file, the particle (record,
// line or type and index) and what is wrong; no store and no temporary files
// are left behind.
TEST_F(Stability, NonFiniteInputIsRejectedNamingTheFileAndTheParticle) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  struct Damage {
    const char* name;
    double value;
    int field;  // 0-2 position, 3-5 velocity, 6 mass
    const char* expected;
  };
  const Damage damages[] = {
      {"x_nan", nan, 0, "has a non-finite coordinate"},  {"y_inf", inf, 1, "has a non-finite coordinate"},
      {"z_minus_inf", -inf, 2, "has a non-finite coordinate"}, {"vx_nan", nan, 3, "has a non-finite velocity"},
      {"vz_inf", inf, 5, "has a non-finite velocity"},   {"mass_nan", nan, 6, "has mass nan"},
      {"mass_inf", inf, 6, "has mass inf"},
  };
  const auto expect_rejected = [&](IngestOptions o, const std::string& file, const std::string& particle,
                                   const std::string& what) {
    try {
      Ingest(o);
      ADD_FAILURE() << file << ": no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kBadInput) << e.what();
      const std::string message = e.what();
      EXPECT_NE(message.find(file), std::string::npos) << message;
      EXPECT_NE(message.find(particle), std::string::npos) << message;
      EXPECT_NE(message.find(what), std::string::npos) << message;
    }
    EXPECT_FALSE(fs::exists(o.output)) << file;
    EXPECT_TRUE(TempIsEmpty()) << file;
  };
  for (const Damage& d : damages) {
    std::vector<Particle> particles = ClumpsInBox(500, 0, 10, 1);
    Particle& bad = particles[321];
    if (d.field < 3) bad.x[d.field] = d.value;
    if (d.field >= 3 && d.field < 6) bad.v[d.field - 3] = static_cast<float>(d.value);
    if (d.field == 6) bad.mass = d.value;
    for (const Width width : {Width::kFloat32, Width::kFloat64}) {
      const std::string file = (dir_ / (std::string(d.name) + (width == Width::kFloat32 ? ".f32" : ".f64"))).string();
      IngestOptions o = Options({file}, "store");
      o.read.format = "raw";
      o.read.raw = RawLayout::Parse(WriteRaw(file, particles, width));
      expect_rejected(o, file, "record 321", d.expected);
    }
    const std::string csv = (dir_ / (std::string(d.name) + ".csv")).string();
    {
      std::ofstream out(csv);
      out << "x,y,z,vx,vy,vz,mass,id\n";
      for (const Particle& p : particles) {
        out << p.x[0] << ',' << p.x[1] << ',' << p.x[2] << ',' << p.v[0] << ',' << p.v[1] << ',' << p.v[2] << ','
            << p.mass << ',' << p.id << '\n';
      }
    }
    const std::string csv_what = d.field < 3 ? "non-finite coordinate" : d.field < 6 ? "non-finite velocity" : "mass";
    expect_rejected(Options({csv}, "store"), csv, "line 323", csv_what);
    if (d.field == 6) continue;  // GADGET masses come from the header's table
    const std::string gadget = (dir_ / (std::string(d.name) + ".gadget")).string();
    {
      synth::GadgetHeader header;
      header.npart[1] = static_cast<std::uint32_t>(particles.size());
      header.npart_total[1] = particles.size();
      header.mass[1] = 1.0;
      synth::GadgetFileWriter writer(gadget, header, synth::GadgetFormat::kFormat2, 4);
      std::vector<float> position, velocity;
      std::vector<std::uint64_t> ids;
      for (const Particle& p : particles) {
        for (int a = 0; a < 3; ++a) position.push_back(static_cast<float>(p.x[a]));
        velocity.insert(velocity.end(), p.v, p.v + 3);
        ids.push_back(p.id);
      }
      writer.Append(position, velocity, ids);
      writer.Close();
      writer.Commit();
    }
    expect_rejected(Options({gadget}, "store"), gadget, "particle 321", d.expected);
  }
}

// ---- Periodic boundary: displacements --------------------------------------

// Two epochs in a periodic box, with the boundary crossings that break naive
// differences: from just inside the upper face to just inside the lower one
// and back, from exactly 0 to just below L, from the upper edge x == L (which
// is x == 0) to 0, a move of exactly L/2 (either image is minimal), and moves
// of nearly a whole box; plus random walkers, in boxes 1e-3, 100 and 1e7 wide.
// Bound: every stored displacement is the minimal image of the true move,
// within the block codec's range quantization (the block's displacement range
// / 131070, at most 2 * L/2 / 131070) plus float32 rounding (4 ulps of L/2), and
// never longer than L/2 by more than that. (IngestTest.
// PeriodicSeriesDisplacementsTakeTheShortWayAcrossTheBoundary covers random
// steps in one box.)
TEST_F(Stability, PeriodicCrossingsStoreTheMinimalImage) {
  for (const double box : {1e-3, 100.0, 1e7}) {
    SCOPED_TRACE("box " + std::to_string(box));
    const double eps = box * 1e-6;
    std::vector<std::pair<Particle, Particle>> moves;
    const auto add = [&](double from, double to) {
      Particle a, b;
      a.x[0] = from;
      b.x[0] = to;
      a.x[1] = b.x[1] = box * 0.25;
      a.x[2] = b.x[2] = box * 0.75;
      a.id = b.id = 100 + moves.size();
      moves.emplace_back(a, b);
    };
    add(box - eps, eps);                  // up through the face: +2 eps
    add(eps, box - eps);                  // down through the face: -2 eps
    add(0, box - eps);                    // -eps
    add(box, 0);                          // the upper edge is x == 0: no move
    add(0.1 * box, 0.6 * box);            // exactly half a box
    add(0.01 * box, 0.99 * box);          // -0.02 box, the short way
    add(std::nextafter(box, 0.0), 0);     // one ulp
    std::mt19937_64 rng(21);
    std::uniform_real_distribution<double> where(0, box), step(-0.3 * box, 0.3 * box);
    for (int i = 0; i < 3000; ++i) {
      const double from = where(rng);
      double to = from + step(rng);
      to -= box * std::floor(to / box);
      add(from, to);
    }
    std::vector<Particle> first, second;
    for (const auto& [a, b] : moves) first.push_back(a), second.push_back(b);
    IngestOptions o = Options({}, "series");
    o.read.format = "raw";
    o.read.raw = RawLayout::Parse(WriteRaw(dir_ / "e0.raw", first, Width::kFloat64));
    WriteRaw(dir_ / "e1.raw", second, Width::kFloat64);
    o.inputs = {(dir_ / "e0.raw").string(), (dir_ / "e1.raw").string()};
    o.read.box_size_override = box;
    o.tree.capacity = 200;
    Ingest(o);
    const TreeCheck check = CheckTree(Dataset::Open(o.output), 0);
    const double half = box / 2;
    const double bound = 2 * half / 131070 * (1 + 1e-6) + 4 * half * 0x1p-23;
    for (const auto& [a, b] : moves) {
      const LeafPoint& leaf = check.leaf_points.at(a.id);
      ASSERT_TRUE(leaf.Has(VectorColumn::kDisplacement));
      double expected = b.x[0] - a.x[0];
      expected -= box * std::nearbyint(expected / box);
      const std::array<float, 3>& displacement = leaf.Vector(VectorColumn::kDisplacement);
      const double stored = displacement[0];
      if (std::fabs(std::fabs(expected) - half) < 1e-9 * box) {
        ASSERT_NEAR(std::fabs(stored), half, bound) << "ID " << a.id << ": half a box either way";
      } else {
        ASSERT_NEAR(stored, expected, bound) << "ID " << a.id << " from " << a.x[0] << " to " << b.x[0];
      }
      ASSERT_LE(std::fabs(stored), half + bound) << "ID " << a.id;
      ASSERT_LE(std::fabs(displacement[1]) + std::fabs(displacement[2]), 2 * bound) << "ID " << a.id;
    }
    fs::remove_all(o.output);
  }
}

}  // namespace
}  // namespace octocosm
