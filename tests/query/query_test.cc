// Indexed queries against brute force: every query must return exactly the
// points that decoding every block of the same level of detail and filtering
// by position returns, while touching fewer blocks and bytes.
#include "query/query.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <random>
#include <set>
#include <tuple>
#include <unistd.h>
#include <unordered_set>

#include "base/error.h"
#include "index/block_codec.h"
#include "index/dataset.h"
#include "ingest/ingest.h"
#include "query/frustum.h"
#include "query/node_selection.h"
#include "query/particle_lookup.h"
#include "query/region.h"
#include "tests/storage/storage_test_util.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

constexpr double kBox = 100.0;

// Clustered particles: Gaussian halos on a uniform background, with IDs and velocities.
void WriteParticles(const fs::path& path, std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(0, kBox);
  std::normal_distribution<double> gauss(0, kBox / 30);
  std::vector<std::array<double, 3>> centres(5);
  for (auto& c : centres) c = {uniform(rng), uniform(rng), uniform(rng)};
  std::ofstream out(path, std::ios::binary);
  for (std::size_t i = 0; i < n; ++i) {
    double x[3];
    for (int a = 0; a < 3; ++a) {
      x[a] = i % 3 == 0 ? uniform(rng) : centres[i % centres.size()][a] + gauss(rng);
      x[a] -= kBox * std::floor(x[a] / kBox);
    }
    const float v[3] = {static_cast<float>(i % 17) - 8.0f, static_cast<float>(i % 5), -1.5f};
    const double mass = 1.0 + static_cast<double>(i % 3);
    const std::uint64_t id = 7 + 2 * i;
    out.write(reinterpret_cast<const char*>(x), sizeof x);
    out.write(reinterpret_cast<const char*>(v), sizeof v);
    out.write(reinterpret_cast<const char*>(&mass), sizeof mass);
    out.write(reinterpret_cast<const char*>(&id), sizeof id);
  }
}

struct Stores {
  fs::path dir;
  std::string bounded;   // non-periodic: the bounding cube
  std::string periodic;  // the same particles in a periodic box of edge kBox
};

Stores* stores = nullptr;

class QueryTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    stores = new Stores;
    stores->dir = fs::temp_directory_path() / ("octocosm-query-test-" + std::to_string(::getpid()));
    fs::remove_all(stores->dir);
    fs::create_directories(stores->dir);
    const fs::path input = stores->dir / "particles.raw";
    WriteParticles(input, 12000, 3);
    IngestOptions o;
    o.inputs = {input.string()};
    o.temp_dir = stores->dir.string();
    o.quiet = true;
    o.page_size = 4096;
    o.threads = 2;
    o.read.format = "raw";
    o.read.raw = RawLayout::Parse("xyz:f64,vel:f32,mass:f64,id:u64");
    o.tree.capacity = 150;
    o.output = stores->bounded = (stores->dir / "bounded").string();
    Ingest(o);
    o.read.box_size_override = kBox;
    o.output = stores->periodic = (stores->dir / "periodic").string();
    Ingest(o);
  }
  static void TearDownTestSuite() {
    fs::remove_all(stores->dir);
    delete stores;
    stores = nullptr;
  }
};

using PointRow = std::tuple<double, double, double, std::uint64_t>;

// Every block of the epoch, decoded whole, with the tree structure.
struct Everything {
  std::map<std::uint64_t, IndexEntry> entries;
  std::map<std::uint64_t, NodePoints> points;
  std::set<std::uint64_t> inner;  // keys with at least one child

  bool IsLeaf(std::uint64_t key) const { return !inner.count(key); }
};

Everything ReadEverything(const Dataset& dataset) {
  Everything all;
  dataset.store().Scan(0, 0, ~std::uint64_t{0}, [&](const IndexEntry& e) {
    all.entries[e.key] = e;
    return true;
  });
  for (const auto& [k, e] : all.entries) {
    const NodeKey key = NodeKey::FromValue(k);
    if (key.level() > 0) all.inner.insert(key.Parent().value());
    all.points[k] = DecodeBlock(dataset.store().ReadBlock({0, k}), kAllColumns, key, dataset.cube(0), "test").points;
  }
  return all;
}

// Independent statements of the regions, by brute force over periodic images.
bool InBox(const double* p, const std::array<double, 3>& lo, const std::array<double, 3>& hi, bool periodic) {
  for (int a = 0; a < 3; ++a) {
    bool inside = false;
    for (int k = periodic ? -3 : 0; k <= (periodic ? 3 : 0); ++k) {
      const double x = p[a] + k * kBox;
      inside |= x >= lo[a] && x <= hi[a];
    }
    if (!inside) return false;
  }
  return true;
}

bool InSphere(const double* p, const std::array<double, 3>& c, double r, bool periodic) {
  double best = INFINITY;
  const int reach = periodic ? 1 : 0;
  for (int i = -reach; i <= reach; ++i)
    for (int j = -reach; j <= reach; ++j)
      for (int k = -reach; k <= reach; ++k) {
        const double dx = p[0] + i * kBox - c[0], dy = p[1] + j * kBox - c[1], dz = p[2] + k * kBox - c[2];
        best = std::min(best, dx * dx + dy * dy + dz * dz);
      }
  return best <= r * r;
}

std::vector<PointRow> BruteForce(const Everything& all, const std::function<bool(NodeKey)>& selected,
                                 const std::function<bool(const double*)>& inside) {
  std::vector<PointRow> rows;
  for (const auto& [k, points] : all.points) {
    if (!selected(NodeKey::FromValue(k))) continue;
    for (std::size_t i = 0; i < points.size(); ++i) {
      const double* p = &points.position[3 * i];
      if (inside(p)) rows.emplace_back(p[0], p[1], p[2], points.id[i]);
    }
  }
  std::sort(rows.begin(), rows.end());
  return rows;
}

std::function<bool(NodeKey)> LevelSet(const Everything& all, int level) {
  return [&all, level](NodeKey key) {
    return key.level() == level || (key.level() < level && all.IsLeaf(key.value()));
  };
}

std::vector<PointRow> QueryRows(const Dataset& dataset, const Region& region, const QueryOptions& options, QueryStats* stats = nullptr) {
  std::vector<PointRow> rows;
  QueryOptions o = options;
  o.columns |= ColumnBit(ColumnId::kId);
  const QueryStats s = RunQuery(dataset, region, o, [&](const QueryBatch& batch) {
    EXPECT_EQ(batch.points.position.size(), 3 * batch.count);
    EXPECT_EQ(batch.points.id.size(), batch.count);
    for (std::size_t i = 0; i < batch.count; ++i) {
      const double* p = &batch.points.position[3 * i];
      rows.emplace_back(p[0], p[1], p[2], batch.points.id[i]);
    }
  });
  if (stats) *stats = s;
  std::sort(rows.begin(), rows.end());
  return rows;
}

int Depth(const Everything& all) { return NodeKey::FromValue(all.entries.rbegin()->first).level(); }

TEST_F(QueryTest, BoxesAndSpheresMatchBruteForceAtEveryLevel) {
  for (const std::string& path : {stores->bounded, stores->periodic}) {
    const Dataset dataset = Dataset::Open(path);
    const bool periodic = dataset.cube(0).periodic;
    ASSERT_EQ(periodic, path == stores->periodic);
    const Everything all = ReadEverything(dataset);
    const int depth = Depth(all);
    ASSERT_GE(depth, 3);
    std::mt19937_64 rng(11);
    // Corners beyond the box, so that regions straddle the faces (and wrap when periodic).
    std::uniform_real_distribution<double> corner(-0.3 * kBox, 1.2 * kBox), extent(0.01 * kBox, 0.6 * kBox);
    std::size_t nonempty = 0, straddling = 0;
    for (int trial = 0; trial < 40; ++trial) {
      const int level = trial % (depth + 2);
      QueryOptions options;
      options.level = level;
      std::array<double, 3> lo, hi;
      for (int a = 0; a < 3; ++a) {
        lo[a] = corner(rng);
        hi[a] = lo[a] + extent(rng);
        straddling += lo[a] < 0 || hi[a] > kBox;
      }
      const auto box = MakeBoxRegion(lo, hi, dataset.cube(0));
      const auto expected_box = BruteForce(all, LevelSet(all, level), [&](const double* p) { return InBox(p, lo, hi, periodic); });
      EXPECT_EQ(QueryRows(dataset, *box, options), expected_box) << "box trial " << trial << " level " << level;
      const std::array<double, 3> centre = lo;
      const double radius = extent(rng);
      const auto sphere = MakeSphereRegion(centre, radius, dataset.cube(0));
      const auto expected_sphere =
          BruteForce(all, LevelSet(all, level), [&](const double* p) { return InSphere(p, centre, radius, periodic); });
      EXPECT_EQ(QueryRows(dataset, *sphere, options), expected_sphere) << "sphere trial " << trial << " level " << level;
      nonempty += !expected_box.empty() + !expected_sphere.empty();
    }
    EXPECT_GT(nonempty, 40u);
    EXPECT_GT(straddling, 20u);
  }
}

// Selection by region (query/particle_lookup.h): the IDs of every particle
// of the leaves in the region, each once; a cap stops reading with the first
// max_ids of them, and a stop request ends it early.
TEST_F(QueryTest, ParticleIdsInRegionAreTheLeavesParticlesUpToTheCap) {
  const Dataset dataset = Dataset::Open(stores->bounded);
  const Everything all = ReadEverything(dataset);
  const std::array<double, 3> lo{10, 20, 5}, hi{70, 60, 80};
  const auto box = MakeBoxRegion(lo, hi, dataset.cube(0));
  std::vector<std::uint64_t> expected;
  for (const PointRow& row : BruteForce(all, [&](NodeKey key) { return all.IsLeaf(key.value()); },
                                        [&](const double* p) { return InBox(p, lo, hi, false); })) {
    expected.push_back(std::get<3>(row));
  }
  std::sort(expected.begin(), expected.end());
  ASSERT_GT(expected.size(), 1000u);

  ParticleIdCollection found = ParticleIdsInRegion(dataset, 0, *box);
  EXPECT_FALSE(found.truncated);
  EXPECT_FALSE(found.stopped);
  std::sort(found.ids.begin(), found.ids.end());
  EXPECT_EQ(found.ids, expected);
  EXPECT_EQ(ParticleIdsInBox(dataset, 0, lo, hi).size(), expected.size());

  const std::size_t cap = expected.size() / 2;
  ParticleIdCollection capped = ParticleIdsInRegion(dataset, 0, *box, cap);
  EXPECT_TRUE(capped.truncated);
  ASSERT_EQ(capped.ids.size(), cap);
  std::sort(capped.ids.begin(), capped.ids.end());
  EXPECT_TRUE(std::includes(expected.begin(), expected.end(), capped.ids.begin(), capped.ids.end()));
  EXPECT_FALSE(ParticleIdsInRegion(dataset, 0, *box, expected.size()).truncated) << "exactly the cap is not more";

  std::stop_source stop;
  stop.request_stop();
  const ParticleIdCollection stopped = ParticleIdsInRegion(dataset, 0, *box, SIZE_MAX, stop.get_token());
  EXPECT_TRUE(stopped.stopped);
  EXPECT_LT(stopped.ids.size(), expected.size()) << "one block at most";
}

TEST_F(QueryTest, PeriodicBoxAcrossTheFaceSelectsTheOtherSide) {
  const Dataset dataset = Dataset::Open(stores->periodic);
  const Everything all = ReadEverything(dataset);
  QueryOptions options;
  options.level = Depth(all);
  // A slab from x = 95 to x = 105 wraps to [95, 100) and [0, 5].
  const auto slab = MakeBoxRegion({95, 0, 0}, {105, kBox, kBox}, dataset.cube(0));
  const auto rows = QueryRows(dataset, *slab, options);
  std::size_t low = 0, high = 0;
  for (const auto& row : rows) {
    const double x = std::get<0>(row);
    EXPECT_TRUE(x >= 95 || x <= 5) << x;
    low += x <= 5;
    high += x >= 95;
  }
  EXPECT_GT(low, 0u);
  EXPECT_GT(high, 0u);
  // The same slab in a non-periodic store stops at the face.
  const Dataset bounded = Dataset::Open(stores->bounded);
  const auto cut = MakeBoxRegion({95, 0, 0}, {105, kBox, kBox}, bounded.cube(0));
  for (const auto& row : QueryRows(bounded, *cut, options)) EXPECT_GE(std::get<0>(row), 95);
}

Camera RandomCamera(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> where(-0.5 * kBox, 1.5 * kBox), fov(20, 100), aspect(0.5, 2), far(20, 250);
  Camera camera;
  camera.position = {where(rng), where(rng), where(rng)};
  std::uniform_real_distribution<double> inside(0, kBox);
  camera.look_at = {inside(rng), inside(rng), inside(rng)};
  camera.up = {0, 0, 1};
  camera.fov_y_degrees = fov(rng);
  camera.aspect = aspect(rng);
  camera.near = 0.5;
  camera.far = far(rng);
  return camera;
}

TEST_F(QueryTest, FrustaMatchBruteForce) {
  const Dataset dataset = Dataset::Open(stores->bounded);
  const Everything all = ReadEverything(dataset);
  const int depth = Depth(all);
  std::mt19937_64 rng(5);
  std::size_t nonempty = 0;
  for (int trial = 0; trial < 30; ++trial) {
    const Camera camera = RandomCamera(rng);
    const Frustum frustum = Frustum::FromCamera(camera);
    const auto region = MakeFrustumRegion(frustum);
    const int level = trial % (depth + 1);
    QueryOptions options;
    options.level = level;
    // The brute-force frustum test: the point's camera-space coordinates.
    const auto f = camera.Forward(), r = camera.Right(), u = camera.TrueUp();
    const double tan_y = std::tan(camera.fov_y_degrees * std::numbers::pi / 360);
    const auto inside = [&](const double* p) {
      const double d[3] = {p[0] - camera.position[0], p[1] - camera.position[1], p[2] - camera.position[2]};
      const double z = d[0] * f[0] + d[1] * f[1] + d[2] * f[2];
      const double x = d[0] * r[0] + d[1] * r[1] + d[2] * r[2];
      const double y = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
      return z >= camera.near && z <= camera.far && std::fabs(x) <= z * tan_y * camera.aspect && std::fabs(y) <= z * tan_y;
    };
    const auto expected = BruteForce(all, LevelSet(all, level), inside);
    EXPECT_EQ(QueryRows(dataset, *region, options), expected) << "frustum trial " << trial;
    nonempty += !expected.empty();
  }
  EXPECT_GT(nonempty, 10u);
}

TEST_F(QueryTest, SmallRegionsTouchFewerBlocks) {
  const Dataset dataset = Dataset::Open(stores->bounded);
  const Everything all = ReadEverything(dataset);
  const int depth = Depth(all);
  const auto in_level = LevelSet(all, depth);
  std::uint64_t level_nodes = 0;
  for (const auto& [k, e] : all.entries) level_nodes += in_level(NodeKey::FromValue(k));
  const Cube& cube = dataset.cube(0);
  const double c = cube.origin[0] + cube.size / 2;
  const auto small = MakeBoxRegion({c, c, c}, {c + 2, c + 2, c + 2}, cube);
  QueryOptions options;
  options.level = depth;
  QueryStats stats;
  QueryRows(dataset, *small, options, &stats);
  EXPECT_GT(stats.reads.blocks, 0u);
  EXPECT_LT(stats.reads.blocks * 4, level_nodes);
  EXPECT_EQ(stats.reads.blocks, stats.nodes_selected);
  const auto everything = MakeEverythingRegion();
  QueryStats full;
  const auto rows = QueryRows(dataset, *everything, options, &full);
  EXPECT_EQ(full.reads.blocks, level_nodes);
  EXPECT_EQ(rows.size(), dataset.points(0));  // the deepest level is every particle
  EXPECT_GT(full.reads.bytes, 4 * stats.reads.bytes);
}

TEST_F(QueryTest, FewerColumnsReadFewerBytesAndTheSamePositions) {
  const Dataset dataset = Dataset::Open(stores->bounded);
  const auto region = MakeSphereRegion({50, 50, 50}, 30, dataset.cube(0));
  QueryOptions options;
  options.level = 3;
  const auto collect = [&](ColumnSet columns, QueryStats& stats) {
    options.columns = columns;
    std::vector<double> positions;
    std::size_t velocities = 0, weights = 0;
    stats = RunQuery(dataset, *region, options, [&](const QueryBatch& b) {
      positions.insert(positions.end(), b.points.position.begin(), b.points.position.end());
      velocities += b.points.velocity.size();
      weights += b.points.weight.size();
      if (!(columns & ColumnBit(ColumnId::kVelocity))) {
        EXPECT_TRUE(b.points.velocity.empty());
      }
      if (!(columns & ColumnBit(ColumnId::kWeight))) {
        EXPECT_TRUE(b.points.weight.empty());
      }
      EXPECT_TRUE(b.points.displacement.empty());
      EXPECT_TRUE(b.points.smoothing.empty() || (columns & ColumnBit(ColumnId::kSmoothing)));
    });
    return std::make_tuple(positions, velocities, weights);
  };
  QueryStats only_positions, with_velocity, all_columns;
  const auto [p1, v1, w1] = collect(ColumnBit(ColumnId::kPosition), only_positions);
  const auto [p2, v2, w2] = collect(ColumnBit(ColumnId::kVelocity) | ColumnBit(ColumnId::kWeight), with_velocity);
  const auto [p3, v3, w3] = collect(kAllColumns, all_columns);
  ASSERT_FALSE(p1.empty());
  EXPECT_EQ(p1, p2);
  EXPECT_EQ(p1, p3);
  EXPECT_EQ(v1, 0u);
  EXPECT_EQ(v2, p1.size());
  EXPECT_EQ(w2, p1.size() / 3);
  EXPECT_EQ(only_positions.reads.blocks, all_columns.reads.blocks);
  EXPECT_LT(only_positions.reads.bytes, with_velocity.reads.bytes);
  EXPECT_LT(with_velocity.reads.bytes, all_columns.reads.bytes);
  // One read for the header plus one per run of adjacent columns; whole blocks when every column is wanted.
  EXPECT_LE(only_positions.reads.reads, 2 * only_positions.reads.blocks);
  EXPECT_EQ(all_columns.reads.reads, all_columns.reads.blocks);
}

// The frontier of a screen-space-error query, as node keys.
std::vector<std::uint64_t> Frontier(const Dataset& dataset, const Region& region, const ScreenErrorView& view) {
  SelectionStats stats;
  std::vector<std::uint64_t> keys;
  for (const IndexEntry& e : SelectByScreenError(dataset, 0, region, view, stats)) keys.push_back(e.key);
  return keys;
}

TEST_F(QueryTest, ScreenSpaceErrorFrontierCoversOnceAndMatchesBruteForce) {
  const Dataset dataset = Dataset::Open(stores->bounded);
  const Everything all = ReadEverything(dataset);
  const Cube& cube = dataset.cube(0);
  std::mt19937_64 rng(8);
  for (int trial = 0; trial < 20; ++trial) {
    ScreenErrorView view;
    view.camera = RandomCamera(rng);
    view.viewport_height = 600;
    view.threshold_pixels = std::pow(2.0, trial % 8);
    const auto region = MakeFrustumRegion(Frustum::FromCamera(view.camera));
    const auto frontier = Frontier(dataset, *region, view);
    const std::unordered_set<std::uint64_t> chosen(frontier.begin(), frontier.end());
    ASSERT_EQ(chosen.size(), frontier.size());
    for (const auto& [k, e] : all.entries) {
      if (!all.IsLeaf(k)) continue;
      const NodeKey leaf = NodeKey::FromValue(k);
      std::size_t covering = 0;
      for (int l = 0; l <= leaf.level(); ++l) covering += chosen.count(leaf.AncestorAt(l).value());
      if (region->MayIntersect(cube.NodeCubeOf(leaf))) EXPECT_EQ(covering, 1u) << leaf.Path();
      else EXPECT_LE(covering, 1u) << leaf.Path();
    }
    // Brute force: a node is drawn when every ancestor is refined and it is not (or is a leaf).
    const auto refine = [&](NodeKey key) {
      return ScreenSpaceError(cube.NodeCubeOf(key), all.entries.at(key.value()).point_count, view) > view.threshold_pixels;
    };
    const auto drawn = [&](NodeKey key) {
      for (int l = 0; l < key.level(); ++l) {
        if (!refine(key.AncestorAt(l))) return false;
      }
      return all.IsLeaf(key.value()) || !refine(key);
    };
    QueryOptions options;
    options.screen_error = view;
    EXPECT_EQ(QueryRows(dataset, *region, options), BruteForce(all, drawn, [&](const double* p) { return region->Contains(p); }))
        << "trial " << trial;
  }
}

TEST_F(QueryTest, SmallerScreenErrorNeverReturnsFewerPoints) {
  const Dataset dataset = Dataset::Open(stores->bounded);
  ScreenErrorView view;
  view.camera.position = {50, 50, 260};  // the whole cube in view
  view.camera.look_at = {50, 50, 50};
  view.camera.up = {0, 1, 0};
  view.camera.fov_y_degrees = 45;
  view.viewport_height = 800;
  const auto region = MakeFrustumRegion(Frustum::FromCamera(view.camera));
  std::uint64_t previous = 0;
  std::vector<std::uint64_t> counts;
  for (double pixels = 512; pixels >= 0.01; pixels /= 2) {
    view.threshold_pixels = pixels;
    QueryOptions options;
    options.screen_error = view;
    const QueryStats stats = RunQuery(dataset, *region, options, [](const QueryBatch&) {});
    EXPECT_GE(stats.points_returned, previous) << pixels << " pixels";
    previous = stats.points_returned;
    counts.push_back(previous);
  }
  EXPECT_LT(counts.front(), counts.back());
  EXPECT_EQ(counts.back(), dataset.points(0));  // fine enough: every leaf
}

TEST_F(QueryTest, BadOptionsAreInvalidArguments) {
  const Dataset dataset = Dataset::Open(stores->bounded);
  const auto everything = MakeEverythingRegion();
  const auto expect_invalid = [&](const QueryOptions& options) {
    try {
      RunQuery(dataset, *everything, options, [](const QueryBatch&) {});
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument) << e.what();
    }
  };
  QueryOptions none;
  expect_invalid(none);
  QueryOptions both;
  both.level = 2;
  both.screen_error = ScreenErrorView{};
  expect_invalid(both);
  QueryOptions epoch;
  epoch.level = 1;
  epoch.epoch = 9;
  expect_invalid(epoch);
  QueryOptions level;
  level.level = 40;
  expect_invalid(level);
  QueryOptions camera;
  camera.screen_error = ScreenErrorView{};
  camera.screen_error->camera.look_at = camera.screen_error->camera.position;
  expect_invalid(camera);
  EXPECT_THROW(MakeBoxRegion({1, 0, 0}, {0, 1, 1}, dataset.cube(0)), Error);
  EXPECT_THROW(MakeSphereRegion({0, 0, 0}, -1, dataset.cube(0)), Error);
}

TEST_F(QueryTest, DamagedColumnIsCorruptionOnlyWhenRead) {
  const fs::path copy = stores->dir / "damaged";
  fs::remove_all(copy);
  fs::copy(stores->bounded, copy, fs::copy_options::recursive);
  std::uint64_t offset = 0;
  std::string page_file;
  {
    const Dataset dataset = Dataset::Open(copy.string());
    const auto entry = dataset.store().Lookup({0, NodeKey::Root().value()});
    ASSERT_TRUE(entry.has_value());
    Bytes prefix(kBlockMaxHeaderSize);
    dataset.store().ReadBlockRange({0, entry->key}, 0, prefix);
    const BlockHeader header = DecodeBlockHeader(prefix, NodeKey::Root(), "test");
    const BlockColumn* velocity = header.Find(ColumnId::kVelocity);
    ASSERT_NE(velocity, nullptr);
    offset = entry->first_page * dataset.store().page_size() + velocity->offset + velocity->length / 2;
    page_file = (copy / dataset.store().epochs()[0].file).string();
  }
  storagetest::FlipByte(page_file, offset, 0x5a);
  const Dataset dataset = Dataset::Open(copy.string());
  const auto everything = MakeEverythingRegion();
  QueryOptions options;
  options.level = 0;
  EXPECT_EQ(RunQuery(dataset, *everything, options, [](const QueryBatch&) {}).points_returned,
            dataset.store().Lookup({0, NodeKey::Root().value()})->point_count);
  options.columns = ColumnBit(ColumnId::kVelocity);
  try {
    RunQuery(dataset, *everything, options, [](const QueryBatch&) {});
    ADD_FAILURE() << "a damaged velocity column went unnoticed";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kCorruption) << e.what();
    EXPECT_NE(std::string(e.what()).find("velocity"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(page_file.substr(page_file.rfind('/') + 1)), std::string::npos) << e.what();
  }
  fs::remove_all(copy);
}

TEST(FrustumTest, ViewMatrixGivesTheSameCamera) {
  // glm::lookAt({1, 2, 3}, {4, 2, 3}, {0, 0, 1}): forward +x, right -y, up +z.
  const std::array<double, 16> view = {0, 0, -1, 0, -1, 0, 0, 0, 0, 1, 0, 0, 2, -3, 1, 1};
  const Camera camera = Camera::FromViewMatrix(view, 60, 1.5, 0.1, 100);
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(camera.position[a], (std::array<double, 3>{1, 2, 3})[a], 1e-12);
  const auto f = camera.Forward();
  EXPECT_NEAR(f[0], 1, 1e-12);
  const auto u = camera.TrueUp();
  EXPECT_NEAR(u[2], 1, 1e-12);
  const Frustum frustum = Frustum::FromCamera(camera);
  const double ahead[3] = {10, 2, 3}, behind[3] = {-5, 2, 3}, beside[3] = {10, 2, 30};
  EXPECT_TRUE(frustum.Contains(ahead));
  EXPECT_FALSE(frustum.Contains(behind));
  EXPECT_FALSE(frustum.Contains(beside));
  EXPECT_THROW(Camera::FromViewMatrix({2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}, 60, 1, 0.1, 10), Error);
}

// A box is contained exactly when all eight of its corners are inside.
TEST(FrustumTest, ContainsBoxIsAllCornersInside) {
  Camera camera;
  camera.position = {0, 0, 0};
  camera.look_at = {1, 0.3, -0.2};
  camera.up = {0, 0, 1};
  camera.fov_y_degrees = 40;
  camera.aspect = 1.6;
  camera.near = 0.5;
  camera.far = 20;
  const Frustum frustum = Frustum::FromCamera(camera);
  std::mt19937_64 random(11);
  std::uniform_real_distribution<double> where(-12, 12), size(0.01, 6);
  int inside = 0, outside = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    const std::array<double, 3> lo = {where(random) + 10, where(random), where(random)};
    const double s = size(random);
    const std::array<double, 3> hi = {lo[0] + s, lo[1] + s, lo[2] + s};
    bool corners = true;
    for (int c = 0; c < 8; ++c) {
      const double corner[3] = {(c & 1) ? hi[0] : lo[0], (c & 2) ? hi[1] : lo[1], (c & 4) ? hi[2] : lo[2]};
      corners &= frustum.Contains(corner);
    }
    ASSERT_EQ(frustum.ContainsBox(lo, hi), corners) << trial;
    (corners ? inside : outside) += 1;
    if (corners) {
      ASSERT_TRUE(frustum.MayIntersectBox(lo, hi));
    }
  }
  EXPECT_GT(inside, 100);
  EXPECT_GT(outside, 100);
}

}  // namespace
}  // namespace octocosm
