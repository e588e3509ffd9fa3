// The ingest pipeline end to end: snapshots in, store out, every invariant of
// the octree checked by reading the store back.
#include "ingest/ingest.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <unordered_map>

#include "base/error.h"
#include "index/block_codec.h"
#include "index/dataset.h"
#include "index/id_index.h"
#include "index/subtree_builder.h"
#include "ingest/snapshot/snapshot_source.h"
#include "storage/store_reader.h"
#include "index/store_verify.h"
#include "tests/ingest/ingest_fixture.h"
#include "tests/ingest/snapshot/gadget_test_file.h"
#include "tests/ingest/store_check.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using namespace testing_support;


// Clustered points in [0, box)^3.
std::vector<Particle> Clustered(std::size_t n, std::uint64_t seed, double box) {
  ClusteredSpec spec;
  spec.size = box;
  return testing_support::Clustered(n, seed, spec);
}

class IngestTest : public IngestFixture {
 protected:
  // Options for inputs written by WriteRaw.
  IngestOptions RawOptions(std::vector<std::string> inputs, const std::string& out) const {
    IngestOptions o = Options(std::move(inputs), out);
    o.read.format = "raw";
    o.read.raw = RawLayout::Parse("xyz:f64,mass:f64,id:u64");
    return o;
  }
};

TEST_F(IngestTest, EveryParticleInExactlyOneLeafWeightsExactPositionsWithinHalfAQuantum) {
  const auto particles = Clustered(60000, 1, 100.0);
  const std::string input = WriteRaw(dir_ / "in.raw", particles);
  IngestOptions o = RawOptions({input}, "store");
  o.tree.capacity = 1000;
  o.max_chunk_points = 8000;  // forces many chunks and re-splits of dense cells
  const IngestReport report = Ingest(o);
  ASSERT_EQ(report.input_points, particles.size());
  EXPECT_GT(report.epochs[0].chunks, 5u);
  EXPECT_TRUE(TempIsEmpty());

  const Dataset dataset = Dataset::Open(o.output);
  const TreeCheck check = CheckTree(dataset, 0);
  ASSERT_EQ(check.leaf_points.size(), particles.size());
  double total = 0;
  const Cube& cube = dataset.cube(0);
  for (const Particle& p : particles) {
    total += p.mass;
    const auto it = check.leaf_points.find(p.id);
    ASSERT_NE(it, check.leaf_points.end()) << "ID " << p.id << " lost";
    const LeafPoint& lp = it->second;
    // A leaf keeps each particle's own mass, to within one integer weight unit.
    EXPECT_NEAR(lp.weight, p.mass, lp.node_mass / static_cast<double>(kWeightTotalUnits)) << "ID " << p.id;
    const double bound = cube.NodeSize(lp.leaf.level()) / 131072.0 * (1 + 1e-9);
    for (int a = 0; a < 3; ++a) ASSERT_LE(std::fabs(lp.x[a] - p.x[a]), bound) << "ID " << p.id << " axis " << a;
  }
  EXPECT_NEAR(report.epochs[0].mass, total, 1e-12 * total);
}

TEST_F(IngestTest, ChunkingDoesNotChangeTheTree) {
  const auto particles = Clustered(30000, 2, 10.0);
  const std::string input = WriteRaw(dir_ / "in.raw", particles);
  IngestOptions whole = RawOptions({input}, "whole");
  whole.tree.capacity = 500;
  IngestOptions chunked = whole;
  chunked.output = (dir_ / "chunked").string();
  chunked.max_chunk_points = 2000;
  chunked.threads = 2;
  IngestOptions streamed = chunked;
  streamed.output = (dir_ / "streamed").string();
  streamed.stream_chunks = true;
  EXPECT_TRUE(Ingest(whole).epochs[0].resident);
  const IngestReport report = Ingest(chunked);
  EXPECT_GT(report.epochs[0].chunks, 10u);
  EXPECT_TRUE(report.epochs[0].resident);
  const IngestReport streamed_report = Ingest(streamed);
  EXPECT_FALSE(streamed_report.epochs[0].resident);
  // The same chunks, but for the end of the resident list, which is cut finer
  // (Chunker::SplitTail).
  EXPECT_GE(report.epochs[0].chunks, streamed_report.epochs[0].chunks);
  const TreeCheck a = CheckTree(Dataset::Open(whole.output), 0);
  const TreeCheck b = CheckTree(Dataset::Open(chunked.output), 0);
  const TreeCheck c = CheckTree(Dataset::Open(streamed.output), 0);
  EXPECT_EQ(FirstDifference(a, b), "") << "the same data must give the same blocks whatever the memory budget";
  EXPECT_EQ(FirstDifference(a, c), "") << "chunks held in place or streamed through buffers give the same blocks";
}

// Chunks are cells of a fixed level; where the data are sparse, a node above
// them can hold no more than `capacity` particles, and the tree must make it
// a leaf, not an inner node over chunk-sized children (the points stored
// twice, and the tree depending on where the chunks were cut: on the thread
// count, through the chunk size). Whatever the chunking, the store must hold
// exactly the blocks of one in-memory build of all the particles.
TEST_F(IngestTest, StoreIsOneWholeBuildWhereverTheChunksAreCut) {
  const auto particles = Clustered(30000, 9, 10.0);
  const std::string input = WriteRaw(dir_ / "in.raw", particles);
  IngestOptions o = RawOptions({input}, "store");
  o.tree.capacity = 500;
  o.neighbours = 0;  // the leaves' density grid, as one BuildSubtree computes it
  const Cube cube = Cube::FromBounds({0, 0, 0}, {10, 10, 10});
  o.cube = cube;
  // The reference: every particle in one BuildSubtree, every node encoded.
  ParticleChunk all;
  for (const Particle& p : particles) {
    all.position.insert(all.position.end(), p.x, p.x + 3);
    all.mass.push_back(p.mass);
    all.type.push_back(0);
    all.id.push_back(p.id);
  }
  std::map<std::uint64_t, Bytes> reference;
  BuildSubtree(all, NodeKey::Root(), cube, o.tree,
               [&](NodeKey key, const NodePoints& node) { reference[key.value()] = EncodeBlock(node, key, cube); });
  std::size_t sparse_top = 0;  // leaves at levels 1-2: the nodes chunks used to cut below
  for (const auto& [key, bytes] : reference) {
    const NodeKey k = NodeKey::FromValue(key);
    const auto child = reference.lower_bound(k.Child(0).value());
    const bool leaf = child == reference.end() || child->first > k.Child(7).value();
    sparse_top += leaf && k.level() >= 1 && k.level() <= 2;
  }
  ASSERT_GT(sparse_top, 3u) << "the data must have sparse nodes above the chunks";
  std::vector<Bytes> first_id_index;  // the ID index's blocks, the same in every setting
  for (const std::uint64_t max_chunk : {0, 400, 3000}) {
    for (const unsigned threads : {1u, 2u}) {
      SCOPED_TRACE("max_chunk_points " + std::to_string(max_chunk) + ", threads " + std::to_string(threads));
      o.output = (dir_ / ("store-" + std::to_string(max_chunk) + "-" + std::to_string(threads))).string();
      o.max_chunk_points = max_chunk;
      o.threads = threads;
      const IngestReport report = Ingest(o);
      const TreeCheck check = CheckTree(Dataset::Open(o.output), 0);
      ASSERT_EQ(check.blocks.size(), reference.size()) << report.epochs[0].chunks << " chunks";
      for (const auto& [key, bytes] : reference) {
        ASSERT_TRUE(check.blocks.count(key)) << NodeKey::FromValue(key).Path();
        ASSERT_EQ(check.blocks.at(key).front(), bytes) << NodeKey::FromValue(key).Path();
      }
      const StoreReader ids = StoreReader::Open(o.output + "/ids");
      std::vector<Bytes> id_index;
      ids.Scan(0, 0, ~std::uint64_t{0}, [&](const IndexEntry& e) { return id_index.push_back(ids.ReadBlock({0, e.key})), true; });
      ASSERT_FALSE(id_index.empty());
      if (first_id_index.empty()) first_id_index = id_index;
      EXPECT_TRUE(id_index == first_id_index) << "the ID index's blocks differ";
    }
  }
}

TEST_F(IngestTest, PeriodicSeriesDisplacementsTakeTheShortWayAcrossTheBoundary) {
  const double box = 50.0;
  auto epoch0 = Clustered(20000, 3, box);
  auto epoch1 = epoch0;
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> step(-2.0, 2.0);
  for (auto& p : epoch1) {
    for (double& x : p.x) {
      x += step(rng);
      x -= box * std::floor(x / box);  // wrapped into [0, box)
    }
  }
  std::shuffle(epoch1.begin(), epoch1.end(), rng);  // a different file order
  IngestOptions o = RawOptions({WriteRaw(dir_ / "e0.raw", epoch0), WriteRaw(dir_ / "e1.raw", epoch1)}, "series");
  o.read.box_size_override = box;
  o.tree.capacity = 800;
  Ingest(o);
  const Dataset dataset = Dataset::Open(o.output);
  ASSERT_EQ(dataset.epoch_count(), 2u);
  EXPECT_TRUE(dataset.cube(0).periodic);
  const TreeCheck first = CheckTree(dataset, 0);
  std::unordered_map<std::uint64_t, const Particle*> next;
  for (const auto& p : epoch1) next[p.id] = &p;
  std::size_t crossings = 0;
  for (const Particle& p : epoch0) {
    const LeafPoint& lp = first.leaf_points.at(p.id);
    ASSERT_TRUE(lp.Has(VectorColumn::kDisplacement));
    for (int a = 0; a < 3; ++a) {
      double expected = next.at(p.id)->x[a] - p.x[a];
      if (std::fabs(expected) > box / 2) {
        ++crossings;
        expected -= box * std::nearbyint(expected / box);
      }
      // Quantized per block between min and max (|d| <= 2): error <= 4 / 131070, plus float rounding.
      ASSERT_NEAR(lp.Vector(VectorColumn::kDisplacement)[a], expected, 4.0 / 131070 + 1e-5) << "ID " << p.id;
    }
  }
  EXPECT_GT(crossings, 100u) << "the test must exercise boundary crossings";
  // The last epoch has nothing to move to; its way back is the way forward reversed.
  const TreeCheck last = CheckTree(dataset, 1);
  EXPECT_FALSE(last.leaf_points.begin()->second.Has(VectorColumn::kDisplacement));
  for (const Particle& p : epoch0) {
    const LeafPoint& back = last.leaf_points.at(p.id);
    const LeafPoint& forward = first.leaf_points.at(p.id);
    ASSERT_TRUE(back.Has(VectorColumn::kPrevDisplacement));
    for (int a = 0; a < 3; ++a) {
      ASSERT_NEAR(back.Vector(VectorColumn::kPrevDisplacement)[a], -forward.Vector(VectorColumn::kDisplacement)[a],
                  back.Bound(VectorColumn::kPrevDisplacement, a) + forward.Bound(VectorColumn::kDisplacement, a));
    }
  }
  // Without velocities there is no Hermite scale to fit, and no velocity links.
  EXPECT_EQ(dataset.columns(0) & (ColumnBit(ColumnId::kNextVelocity) | ColumnBit(ColumnId::kPrevVelocity)), 0u);
  EXPECT_EQ(dataset.columns(1) & (ColumnBit(ColumnId::kNextVelocity) | ColumnBit(ColumnId::kPrevVelocity)), 0u);
  ASSERT_TRUE(dataset.link_to_next(0).has_value());
  EXPECT_EQ(dataset.link_to_next(0)->velocity_scale, 0.0);
  EXPECT_EQ(dataset.link_to_next(0)->fit_residual, 1.0);
  EXPECT_EQ(dataset.link_to_next(0)->matched, epoch0.size());
  // The ID index finds every particle in both epochs.
  IdIndexReader ids(dataset.id_index_directory());
  for (std::size_t i = 0; i < epoch0.size(); i += 97) {
    EXPECT_EQ(ids.Find(0, epoch0[i].id), first.leaf_points.at(epoch0[i].id).leaf);
    EXPECT_EQ(ids.Find(1, epoch0[i].id), last.leaf_points.at(epoch0[i].id).leaf);
  }
  EXPECT_FALSE(ids.Find(0, 7).has_value());
}

// A particle of a series with velocities, as a raw record
// "xyz:f64,vel:f32,mass:f64,id:u64".
struct Moving {
  double x[3];
  float v[3];
  double mass;
  std::uint64_t id;
};

std::string WriteMovingRaw(const fs::path& path, const std::vector<Moving>& particles) {
  std::ofstream out(path, std::ios::binary);
  for (const Moving& p : particles) {
    out.write(reinterpret_cast<const char*>(p.x), sizeof p.x);
    out.write(reinterpret_cast<const char*>(p.v), sizeof p.v);
    out.write(reinterpret_cast<const char*>(&p.mass), sizeof p.mass);
    out.write(reinterpret_cast<const char*>(&p.id), sizeof p.id);
  }
  return path.string();
}

double MinimalImage(double d, double box) { return d - box * std::nearbyint(d / box); }

// Three epochs in a periodic box: particles move by exactly
// step * (v_e + v_e+1) / 2, so the fitted velocity scale must be the step;
// some particles leave after epoch 0 and others arrive in epoch 1.
TEST_F(IngestTest, SeriesLinksEveryParticleToBothNeighbours) {
  const double box = 50.0, step = 0.25;
  const int kEpochs = 3;
  std::mt19937_64 rng(21);
  std::normal_distribution<float> velocity(0, 6), kick(0, 1);
  std::vector<std::unordered_map<std::uint64_t, Moving>> epochs(kEpochs);
  for (const Particle& p : Clustered(12000, 22, box)) {
    Moving m{{p.x[0], p.x[1], p.x[2]}, {velocity(rng), velocity(rng), velocity(rng)}, p.mass, p.id};
    epochs[0][m.id] = m;
  }
  std::uint64_t left = 0, arrived = 0;
  for (int e = 1; e < kEpochs; ++e) {
    for (const auto& [id, before] : epochs[e - 1]) {
      if (e == 1 && id % 50 == 7) {
        ++left;  // gone after epoch 0
        continue;
      }
      Moving m = before;
      for (int a = 0; a < 3; ++a) {
        m.v[a] = before.v[a] + kick(rng);
        const double moved = before.x[a] + step * 0.5 * (static_cast<double>(before.v[a]) + m.v[a]);
        m.x[a] = moved - box * std::floor(moved / box);
      }
      epochs[e][id] = m;
    }
    if (e == 1) {
      std::uniform_real_distribution<double> anywhere(0, box);
      for (std::uint64_t k = 0; k < 300; ++k, ++arrived) {
        Moving m{{anywhere(rng), anywhere(rng), anywhere(rng)}, {velocity(rng), velocity(rng), velocity(rng)}, 1.0,
                 900000 + k};
        epochs[1][m.id] = m;
      }
    }
  }
  std::vector<std::string> inputs;
  for (int e = 0; e < kEpochs; ++e) {
    std::vector<Moving> file;
    for (const auto& [id, m] : epochs[e]) file.push_back(m);
    std::shuffle(file.begin(), file.end(), rng);  // file order is not ID order
    inputs.push_back(WriteMovingRaw(dir_ / ("e" + std::to_string(e) + ".raw"), file));
  }
  IngestOptions o = Options(inputs, "series");
  o.read.format = "raw";
  o.read.raw = RawLayout::Parse("xyz:f64,vel:f32,mass:f64,id:u64");
  o.read.box_size_override = box;
  o.tree.capacity = 400;
  const IngestReport report = Ingest(o);
  EXPECT_TRUE(TempIsEmpty());
  ASSERT_EQ(report.epochs.size(), 3u);
  EXPECT_EQ(report.epochs[0].missing_in_next, left);
  EXPECT_EQ(report.epochs[0].missing_in_prev, 0u);
  EXPECT_EQ(report.epochs[1].missing_in_prev, arrived);
  EXPECT_EQ(report.epochs[1].missing_in_next, 0u);
  EXPECT_EQ(report.epochs[2].missing_in_prev, 0u);

  const Dataset dataset = Dataset::Open(o.output);
  const VerifyReport verified = VerifyStore(o.output);
  EXPECT_TRUE(verified.faults.empty()) << verified.faults.front();
  std::vector<TreeCheck> trees;
  for (std::uint32_t e = 0; e < kEpochs; ++e) trees.push_back(CheckTree(dataset, e));

  using V = VectorColumn;
  std::size_t forward_crossings = 0, backward_crossings = 0;
  for (int e = 0; e < kEpochs; ++e) {
    SCOPED_TRACE("epoch " + std::to_string(e));
    const bool has_next = e + 1 < kEpochs, has_prev = e > 0;
    // Which columns each epoch carries: the links only where a neighbour exists.
    const ColumnSet columns = dataset.columns(static_cast<std::uint32_t>(e));
    EXPECT_EQ((columns & ColumnBit(ColumnId::kNextVelocity)) != 0, has_next);
    EXPECT_EQ((columns & ColumnBit(ColumnId::kPrevVelocity)) != 0, has_prev);
    EXPECT_EQ(dataset.link_to_next(static_cast<std::uint32_t>(e)).has_value(), has_next);
    ASSERT_EQ(trees[e].leaf_points.size(), epochs[e].size());
    for (const auto& [id, lp] : trees[e].leaf_points) {
      const Moving& truth = epochs[e].at(id);
      ASSERT_EQ(lp.Has(V::kDisplacement), has_next);
      ASSERT_EQ(lp.Has(V::kNextVelocity), has_next);
      ASSERT_EQ(lp.Has(V::kPrevDisplacement), has_prev);
      ASSERT_EQ(lp.Has(V::kPrevVelocity), has_prev);
      for (int a = 0; a < 3; ++a) ASSERT_NEAR(lp.Vector(V::kVelocity)[a], truth.v[a], lp.Bound(V::kVelocity, a)) << id;
      if (has_next) {
        const auto next = epochs[e + 1].find(id);
        for (int a = 0; a < 3; ++a) {
          if (next == epochs[e + 1].end()) {  // gone: zeros, to within the block's quantization
            ASSERT_NEAR(lp.Vector(V::kDisplacement)[a], 0.0f, lp.Bound(V::kDisplacement, a)) << id;
            ASSERT_NEAR(lp.Vector(V::kNextVelocity)[a], 0.0f, lp.Bound(V::kNextVelocity, a)) << id;
            continue;
          }
          const double moved = next->second.x[a] - truth.x[a];
          forward_crossings += std::fabs(moved) > box / 2;
          ASSERT_NEAR(lp.Vector(V::kDisplacement)[a], MinimalImage(moved, box), lp.Bound(V::kDisplacement, a)) << id;
          // The next epoch's own velocity column, as that epoch stores it.
          const LeafPoint& later = trees[e + 1].leaf_points.at(id);
          ASSERT_NEAR(lp.Vector(V::kNextVelocity)[a], later.Vector(V::kVelocity)[a],
                      lp.Bound(V::kNextVelocity, a) + later.Bound(V::kVelocity, a)) << id;
          ASSERT_NEAR(lp.Vector(V::kNextVelocity)[a], next->second.v[a], lp.Bound(V::kNextVelocity, a)) << id;
        }
      }
      if (has_prev) {
        const auto prev = epochs[e - 1].find(id);
        for (int a = 0; a < 3; ++a) {
          if (prev == epochs[e - 1].end()) {  // arrived: zeros, to within the block's quantization
            ASSERT_NEAR(lp.Vector(V::kPrevDisplacement)[a], 0.0f, lp.Bound(V::kPrevDisplacement, a)) << id;
            ASSERT_NEAR(lp.Vector(V::kPrevVelocity)[a], 0.0f, lp.Bound(V::kPrevVelocity, a)) << id;
            continue;
          }
          const double moved_back = prev->second.x[a] - truth.x[a];
          backward_crossings += std::fabs(moved_back) > box / 2;
          ASSERT_NEAR(lp.Vector(V::kPrevDisplacement)[a], MinimalImage(moved_back, box), lp.Bound(V::kPrevDisplacement, a)) << id;
          // Exactly the way forward reversed, to within the two blocks' quantization.
          const LeafPoint& earlier = trees[e - 1].leaf_points.at(id);
          ASSERT_NEAR(lp.Vector(V::kPrevDisplacement)[a], -earlier.Vector(V::kDisplacement)[a],
                      lp.Bound(V::kPrevDisplacement, a) + earlier.Bound(V::kDisplacement, a)) << id;
          ASSERT_NEAR(lp.Vector(V::kPrevVelocity)[a], earlier.Vector(V::kVelocity)[a],
                      lp.Bound(V::kPrevVelocity, a) + earlier.Bound(V::kVelocity, a)) << id;
          ASSERT_NEAR(lp.Vector(V::kPrevVelocity)[a], prev->second.v[a], lp.Bound(V::kPrevVelocity, a)) << id;
        }
      }
    }
  }
  EXPECT_GT(forward_crossings, 50u) << "the test must exercise boundary crossings";
  EXPECT_EQ(forward_crossings, backward_crossings);

  // Every displacement is exactly step * vbar, so every particle agrees on the scale.
  for (std::uint32_t e = 0; e + 1 < kEpochs; ++e) {
    const EpochLink& link = *dataset.link_to_next(e);
    EXPECT_NEAR(link.velocity_scale, step, 1e-9 * step) << e;
    EXPECT_NEAR(link.least_squares_scale, step, 1e-9 * step) << e;
    EXPECT_LT(link.fit_residual, 1e-6) << e;
    EXPECT_NEAR(link.inlier_fraction, 1.0, 1e-12) << e;
    EXPECT_EQ(link.matched, e == 0 ? epochs[0].size() - left : epochs[1].size());
  }

  // Out-of-core sort runs, small chunks and two threads give the same blocks.
  IngestOptions small = o;
  small.output = (dir_ / "small").string();
  small.memory_budget = 32 << 20;
  small.sort_run_points = 1500;
  small.max_chunk_points = 2500;
  small.threads = 2;
  Ingest(small);
  EXPECT_TRUE(TempIsEmpty());
  const Dataset other = Dataset::Open(small.output);
  for (std::uint32_t e = 0; e < kEpochs; ++e) EXPECT_EQ(FirstDifference(trees[e], CheckTree(other, e)), "") << e;
}

TEST_F(IngestTest, IdIndexFindsEveryParticleWhetherItsPairsWerePlacedOrSorted) {
  // IDs 1000 + 3i fit a table (one slot per value of their range); IDs
  // 2^40 apart do not, and go through the external sorter.
  for (const bool sparse : {false, true}) {
    SCOPED_TRACE(sparse ? "sparse IDs" : "compact IDs");
    auto particles = Clustered(12000, 9, 20.0);
    if (sparse) {
      for (std::size_t i = 0; i < particles.size(); ++i) particles[i].id = (std::uint64_t{i} + 1) << 40;
    }
    const std::string name = sparse ? "sparse" : "compact";
    IngestOptions o = RawOptions({WriteRaw(dir_ / (name + ".raw"), particles)}, name);
    o.tree.capacity = 500;
    o.max_chunk_points = 2000;
    const IngestReport report = Ingest(o);
    ASSERT_EQ(report.epochs.size(), 1u);
    EXPECT_EQ(report.epochs[0].ids_sorted, sparse);
    const Dataset dataset = Dataset::Open(o.output);
    const TreeCheck check = CheckTree(dataset, 0);
    IdIndexReader ids(dataset.id_index_directory());
    for (const Particle& p : particles) ASSERT_EQ(ids.Find(0, p.id), check.leaf_points.at(p.id).leaf) << p.id;
    EXPECT_FALSE(ids.Find(0, sparse ? (std::uint64_t{5} << 40) + 1 : 1001).has_value());
    EXPECT_FALSE(ids.Find(0, 0).has_value());
    EXPECT_FALSE(ids.Find(0, ~std::uint64_t{0}).has_value());
  }
  EXPECT_TRUE(TempIsEmpty());
}

TEST_F(IngestTest, TheIdIndexKeepsPagesOfAtLeast64KiB) {
  // The store takes the page size asked for; the ID index's buckets fill a
  // page each, so its store keeps 64 KiB pages unless larger ones are asked.
  const auto particles = Clustered(3000, 3, 20.0);
  const std::string input = WriteRaw(dir_ / "in.raw", particles);
  for (const std::uint32_t page_size : {4096u, 65536u, 262144u}) {
    SCOPED_TRACE(page_size);
    IngestOptions o = RawOptions({input}, "pages-" + std::to_string(page_size));
    o.page_size = page_size;
    Ingest(o);
    EXPECT_EQ(StoreReader::Open(o.output).page_size(), page_size);
    EXPECT_EQ(StoreReader::Open((fs::path(o.output) / "ids").string()).page_size(), std::max(page_size, 65536u));
    IdIndexReader ids(Dataset::Open(o.output).id_index_directory());
    for (const Particle& p : particles) ASSERT_TRUE(ids.Find(0, p.id).has_value()) << p.id;
  }
}

TEST_F(IngestTest, OutOfCoreSortRunsGiveTheSameSeries) {
  const auto e0 = Clustered(20000, 5, 20.0);
  auto e1 = e0;
  for (auto& p : e1) p.x[0] = std::min(p.x[0] * 0.9 + 1.0, 19.9);
  IngestOptions big = RawOptions({WriteRaw(dir_ / "e0.raw", e0), WriteRaw(dir_ / "e1.raw", e1)}, "big");
  big.tree.capacity = 700;
  IngestOptions small = big;
  small.output = (dir_ / "small").string();
  small.memory_budget = 32 << 20;
  small.sort_run_points = 1500;  // 14 sorted runs per epoch, merged
  small.max_chunk_points = 3000;
  Ingest(big);
  Ingest(small);
  for (std::uint32_t e = 0; e < 2; ++e) {
    EXPECT_EQ(FirstDifference(CheckTree(Dataset::Open(big.output), e), CheckTree(Dataset::Open(small.output), e)), "");
  }
  EXPECT_TRUE(TempIsEmpty());
}

// `particles` as a GADGET snapshot of two files (types 1 and 2, table
// masses, 4-byte IDs, float positions) in a periodic box of 100, little-
// or big-endian; returns the name of the set.
std::string WriteGadgetSet(const fs::path& dir, const std::string& name, const std::vector<Particle>& particles,
                           bool big_endian) {
  const std::size_t half = particles.size() / 2;
  for (int f = 0; f < 2; ++f) {
    const std::size_t begin = f == 0 ? 0 : half, end = f == 0 ? half : particles.size();
    const auto type1 = static_cast<std::int32_t>((end - begin) / 3);  // the rest are type 2
    GadgetSpec spec;
    spec.big_endian = big_endian;
    spec.num_files = 2;
    spec.npart = {0, type1, static_cast<std::int32_t>(end - begin) - type1, 0, 0, 0};
    spec.total = std::array<std::uint32_t, 6>{};
    spec.mass_table = {0, 2.5, 0.75, 0, 0, 0};
    for (std::size_t i = begin; i < end; ++i) {
      for (int a = 0; a < 3; ++a) {
        spec.position.push_back(particles[i].x[a]);
        spec.velocity.push_back(static_cast<double>(i % 17) - a);
      }
      spec.ids.push_back(particles[i].id);
    }
    WriteBytes((dir / (name + "." + std::to_string(f))).string(), EncodeGadget(spec));
  }
  return (dir / name).string();
}

// A GADGET snapshot in this machine's byte order is mapped, not copied
// (ResidentEpoch::Map); its other-endian twin is read through the source.
// Both give the same store, and so does a mapped snapshot with a point the
// read must wrap into the box (a little outside it), which makes ingest read
// it instead.
TEST_F(IngestTest, MappedAndReadGadgetSnapshotsGiveTheSameStore) {
  static_assert(std::endian::native == std::endian::little, "the mapped files are written little-endian");
  auto particles = Clustered(30000, 12, 100.0);
  particles[20000].x[2] = 0.5;  // a float, and one box over (below) exactly too
  IngestOptions mapped = Options({WriteGadgetSet(dir_, "little", particles, false)}, "mapped");
  mapped.tree.capacity = 500;
  mapped.neighbours = 0;  // a neighbour pass hands out the lengths with copied chunks
  mapped.max_chunk_points = 3000;
  mapped.threads = 2;
  IngestOptions read = mapped;
  read.inputs = {WriteGadgetSet(dir_, "big", particles, true)};
  read.output = (dir_ / "read").string();
  const IngestReport mapped_report = Ingest(mapped);
  const IngestReport read_report = Ingest(read);
  ASSERT_TRUE(mapped_report.epochs[0].resident);
  EXPECT_TRUE(mapped_report.epochs[0].mapped);
  EXPECT_TRUE(read_report.epochs[0].resident);
  EXPECT_FALSE(read_report.epochs[0].mapped);
  EXPECT_EQ(mapped_report.epochs[0].ids_sorted, false) << "the IDs were counted dense from the mapped files";
  const TreeCheck reference = CheckTree(Dataset::Open(read.output), 0);
  EXPECT_EQ(reference.leaf_points.size(), particles.size());
  EXPECT_EQ(FirstDifference(CheckTree(Dataset::Open(mapped.output), 0), reference), "");

  particles[20000].x[2] = 100.5;  // outside the box, within kPeriodicBoxTolerance of it
  IngestOptions outside = mapped;
  outside.inputs = {WriteGadgetSet(dir_, "outside", particles, false)};
  outside.output = (dir_ / "outside").string();
  const IngestReport outside_report = Ingest(outside);
  EXPECT_FALSE(outside_report.epochs[0].mapped);
  EXPECT_EQ(FirstDifference(CheckTree(Dataset::Open(outside.output), 0), reference), "");
  EXPECT_TRUE(TempIsEmpty());
}

// The smoothing length a gas particle is given in the snapshots of the
// smoothing tests: 0 ("not given") for every seventh ID, else 0.2 to 1.3
// (in a box of 100), and another one in every epoch.
float GivenSmoothing(std::uint64_t id, int epoch = 0) {
  if (id % 7 == 4) return 0.0f;
  return (0.2f + static_cast<float>(id % 113) * 0.01f) * (1.0f + 0.5f * static_cast<float>(epoch));
}

// `particles` as a format 2 GADGET snapshot of two files in a periodic box
// of 100, the first two fifths of each file's particles gas (type 0) with
// GivenSmoothing(id, epoch) in the HSML block, the rest dark matter; table
// masses, float positions, this machine's byte order: a snapshot ingest
// would map from its files but for the HSML block.
std::string WriteGasSet(const fs::path& dir, const std::string& name, const std::vector<Particle>& particles,
                        int epoch = 0) {
  const std::size_t half = particles.size() / 2;
  for (int f = 0; f < 2; ++f) {
    const std::size_t begin = f == 0 ? 0 : half, end = f == 0 ? half : particles.size();
    const auto gas = static_cast<std::int32_t>((end - begin) * 2 / 5);
    GadgetSpec spec;
    spec.format = 2;
    spec.num_files = 2;
    spec.npart = {gas, static_cast<std::int32_t>(end - begin) - gas, 0, 0, 0, 0};
    spec.total = std::array<std::uint32_t, 6>{};
    spec.mass_table = {0.5, 2.5, 0, 0, 0, 0};
    for (std::size_t i = begin; i < end; ++i) {
      for (int a = 0; a < 3; ++a) {
        spec.position.push_back(particles[i].x[a]);
        spec.velocity.push_back(static_cast<double>(i % 17) - a);
      }
      spec.ids.push_back(particles[i].id);
      if (i < begin + static_cast<std::size_t>(gas)) spec.hsml.push_back(GivenSmoothing(particles[i].id, epoch));
    }
    WriteBytes((dir / (name + "." + std::to_string(f))).string(), EncodeGadget(spec));
  }
  return (dir / name).string();
}

// Checks `check` (a store of particles written by WriteGasSet) against
// `reference` (the same particles ingested without smoothing lengths): the
// same nodes, every inner node the same block; each gas particle with a
// given length holds it to the codec's precision, and every other particle
// the length it had without the column. Counts the given ones in `given`.
void ExpectGivenSmoothing(const TreeCheck& check, const TreeCheck& reference, int epoch, std::size_t& given) {
  ASSERT_EQ(check.leaf_points.size(), reference.leaf_points.size());
  std::set<std::uint64_t> leaves;
  for (const auto& [id, p] : check.leaf_points) leaves.insert(p.leaf.value());
  ASSERT_EQ(check.blocks.size(), reference.blocks.size());
  for (const auto& [key, blocks] : check.blocks) {
    ASSERT_TRUE(reference.blocks.count(key)) << NodeKey::FromValue(key).Path();
    if (!leaves.count(key)) {
      EXPECT_EQ(blocks, reference.blocks.at(key)) << "inner node " << NodeKey::FromValue(key).Path();
    }
  }
  for (const auto& [id, p] : check.leaf_points) {
    const LeafPoint& without = reference.leaf_points.at(id);
    ASSERT_EQ(p.leaf, without.leaf) << "ID " << id;
    const float h = p.type == 0 ? GivenSmoothing(id, epoch) : 0.0f;
    if (h > 0) {
      ++given;
      ASSERT_NEAR(p.smoothing, h, 2e-4 * h) << "ID " << id << " in " << p.leaf.Path();
    } else {
      ASSERT_EQ(p.smoothing, without.smoothing) << "ID " << id << " (type " << int(p.type) << ")";
    }
  }
}

// By default a leaf point's smoothing length is the radius holding its 32
// nearest neighbours in the whole snapshot (ingest/smoothing_pass.h), the
// same whether the epoch is held in memory or streamed through chunk
// buffers: checked against brute force to the codec's precision (2e-4).
TEST_F(IngestTest, LeavesCarryTheRadiiOfTheirNearestNeighbours) {
  const auto particles = Clustered(20000, 41, 100.0);
  const std::string input = WriteRaw(dir_ / "in.raw", particles);
  IngestOptions resident = RawOptions({input}, "resident");
  resident.tree.capacity = 500;
  resident.max_chunk_points = 3000;
  resident.threads = 2;
  IngestOptions streamed = resident;
  streamed.output = (dir_ / "streamed").string();
  streamed.stream_chunks = true;
  IngestOptions grid = resident;
  grid.output = (dir_ / "grid").string();
  grid.neighbours = 0;
  EXPECT_TRUE(Ingest(resident).epochs[0].resident);
  EXPECT_FALSE(Ingest(streamed).epochs[0].resident);
  Ingest(grid);
  EXPECT_TRUE(TempIsEmpty());
  const TreeCheck held = CheckTree(Dataset::Open(resident.output), 0);
  EXPECT_EQ(FirstDifference(held, CheckTree(Dataset::Open(streamed.output), 0)), "");
  const TreeCheck by_grid = CheckTree(Dataset::Open(grid.output), 0);
  std::size_t checked = 0, unlike_grid = 0;
  for (std::size_t i = 0; i < particles.size(); i += 7) {
    std::vector<double> distances;
    for (const Particle& q : particles) {
      double s = 0;
      for (int a = 0; a < 3; ++a) s += (q.x[a] - particles[i].x[a]) * (q.x[a] - particles[i].x[a]);
      distances.push_back(std::sqrt(s));
    }
    std::nth_element(distances.begin(), distances.begin() + 31, distances.end());
    const double truth = distances[31];
    const LeafPoint& p = held.leaf_points.at(particles[i].id);
    ASSERT_NEAR(p.smoothing, truth, 2e-4 * truth) << "ID " << particles[i].id;
    unlike_grid += std::abs(by_grid.leaf_points.at(particles[i].id).smoothing - truth) > 0.01 * truth;
    ++checked;
  }
  EXPECT_GT(unlike_grid, checked / 2) << "the density grid's lengths are not the neighbours' radii";
}

// The gas's smoothing lengths from the snapshot reach the leaves, whether the
// epoch is held in memory whole or streamed through chunk buffers that spill
// to temporary files (the budget's smallest, 32 MiB, buffers some 170,000
// points); both give the same store. Such a snapshot is read, not mapped
// (a mapping has no place for the lengths), and the same files read
// without their lengths are mapped.
TEST_F(IngestTest, GivenSmoothingLengthsReachTheLeavesHeldInMemoryOrStreamed) {
  const auto particles = Clustered(200000, 31, 100.0);
  const std::string input = WriteGasSet(dir_, "gas", particles);
  IngestOptions resident = Options({input}, "resident");
  resident.tree.capacity = 1000;
  resident.max_chunk_points = 20000;
  resident.threads = 2;
  resident.neighbours = 0;  // the dark matter's lengths from the density grid, as without the column
  resident.tree.coarse = CoarsePoints::kSample;  // inner nodes keep particles, so they compare with the reference's
  IngestOptions streamed = resident;
  streamed.output = (dir_ / "streamed").string();
  streamed.stream_chunks = true;
  streamed.memory_budget = std::uint64_t{32} << 20;
  IngestOptions reference = resident;
  reference.output = (dir_ / "reference").string();
  reference.read.read_smoothing = false;
  const IngestReport resident_report = Ingest(resident);
  const IngestReport streamed_report = Ingest(streamed);
  const IngestReport reference_report = Ingest(reference);
  EXPECT_TRUE(resident_report.epochs[0].resident);
  EXPECT_FALSE(resident_report.epochs[0].mapped);
  EXPECT_TRUE(reference_report.epochs[0].mapped) << "the files are mappable but for the smoothing lengths";
  EXPECT_FALSE(streamed_report.epochs[0].resident);
  EXPECT_GT(streamed_report.epochs[0].spilled_points, particles.size() / 10) << "chunks must go through files";
  EXPECT_GT(streamed_report.epochs[0].chunks, 10u);
  EXPECT_TRUE(TempIsEmpty());

  const TreeCheck without = CheckTree(Dataset::Open(reference.output), 0);
  const TreeCheck held = CheckTree(Dataset::Open(resident.output), 0);
  const TreeCheck spilled = CheckTree(Dataset::Open(streamed.output), 0);
  std::size_t given = 0;
  ExpectGivenSmoothing(held, without, 0, given);
  EXPECT_GT(given, particles.size() / 4);
  EXPECT_EQ(FirstDifference(held, spilled), "") << "held in memory or streamed, the same blocks";
  EXPECT_NE(FirstDifference(held, without), "") << "the given lengths must show in the leaves";
}

// A series with IDs goes through the sort by ID and the epoch join; the
// lengths travel beside the sorted particles, in runs merged from files when
// the runs are small, and each epoch keeps its own.
TEST_F(IngestTest, GivenSmoothingLengthsTravelThroughTheSortOfASeries) {
  const auto e0 = Clustered(20000, 32, 100.0);
  auto e1 = e0;
  std::mt19937_64 rng(33);
  for (auto& p : e1) p.x[0] = std::min(p.x[0] * 0.95 + 2.0, 99.9);
  std::shuffle(e1.begin(), e1.end(), rng);  // another file order: other particles are gas
  const std::vector<std::string> inputs = {WriteGasSet(dir_, "e0", e0, 0), WriteGasSet(dir_, "e1", e1, 1)};
  IngestOptions o = Options(inputs, "series");
  o.tree.capacity = 700;
  o.tree.coarse = CoarsePoints::kSample;  // inner nodes keep particles, so they compare with the reference's
  IngestOptions small = o;
  small.output = (dir_ / "small").string();
  small.sort_run_points = 1500;  // 14 sorted runs per epoch, merged
  small.max_chunk_points = 3000;
  small.stream_chunks = true;
  IngestOptions reference = o;
  reference.output = (dir_ / "reference").string();
  reference.read.read_smoothing = false;
  Ingest(o);
  Ingest(small);
  Ingest(reference);
  EXPECT_TRUE(TempIsEmpty());
  for (int e = 0; e < 2; ++e) {
    SCOPED_TRACE("epoch " + std::to_string(e));
    const TreeCheck check = CheckTree(Dataset::Open(o.output), static_cast<std::uint32_t>(e));
    std::size_t given = 0;
    ExpectGivenSmoothing(check, CheckTree(Dataset::Open(reference.output), static_cast<std::uint32_t>(e)), e, given);
    EXPECT_GT(given, e0.size() / 4);
    EXPECT_EQ(FirstDifference(check, CheckTree(Dataset::Open(small.output), static_cast<std::uint32_t>(e))), "");
  }
}

TEST_F(IngestTest, ANonFiniteCoordinateInAMappableSnapshotIsReported) {
  auto particles = Clustered(5000, 13, 100.0);
  particles[4000].x[0] = std::nan("");  // in the second file, of type 2
  IngestOptions o = Options({WriteGadgetSet(dir_, "nan", particles, false)}, "nan-store");
  try {
    Ingest(o);
    ADD_FAILURE() << "no error";
  } catch (const Error& error) {
    EXPECT_EQ(error.kind(), ErrorKind::kBadInput);
    EXPECT_NE(std::string(error.what()).find((dir_ / "nan.1").string()), std::string::npos) << error.what();
    EXPECT_NE(std::string(error.what()).find("non-finite coordinate"), std::string::npos) << error.what();
  }
  EXPECT_FALSE(fs::exists(o.output));
  EXPECT_TRUE(TempIsEmpty());
}

TEST_F(IngestTest, MalformedInputLeavesNoStoreAndNoTemporaryFiles) {
  auto particles = Clustered(5000, 6, 1.0);
  particles[1234].x[1] = std::nan("");
  IngestOptions o = RawOptions({WriteRaw(dir_ / "nan.raw", particles)}, "store");
  try {
    Ingest(o);
    FAIL() << "NaN coordinates must be rejected";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    EXPECT_NE(std::string(e.what()).find("nan.raw"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.output));
  EXPECT_TRUE(TempIsEmpty());

  // A truncated record: the file size is not a multiple of the record size.
  {
    std::ofstream out(dir_ / "short.raw", std::ios::binary);
    const char bytes[50] = {};
    out.write(bytes, sizeof bytes);
  }
  o.inputs = {(dir_ / "short.raw").string()};
  EXPECT_THROW(Ingest(o), Error);
  EXPECT_FALSE(fs::exists(o.output));
  EXPECT_TRUE(TempIsEmpty());

  // An output that already holds a store is refused and left alone.
  o.inputs = {WriteRaw(dir_ / "good.raw", Clustered(100, 7, 1.0))};
  Ingest(o);
  EXPECT_THROW(Ingest(o), Error);
  EXPECT_NO_THROW(Dataset::Open(o.output));
}


// Particle IDs must be unique, whichever way ingest gathers them: the ID
// table (IDs in a compact range), sorted ID pairs (IDs far apart) or the
// sorted epochs of a series. The error names the file and a repeated ID, and
// nothing is left behind; --no-ids ingests the particles without them.
TEST_F(IngestTest, DuplicateIdsAreRefusedNamingTheFileAndAnId) {
  auto particles = Clustered(6000, 31, 50.0);
  particles[4000].id = particles[17].id;
  const std::string repeated = "ID " + std::to_string(particles[17].id) + " is given to more than one particle";
  const std::string dense = WriteRaw(dir_ / "dense.raw", particles);
  auto wide_particles = particles;
  for (std::size_t i = 0; i < wide_particles.size(); ++i) wide_particles[i].id = (std::uint64_t{1} << 50) + (i << 30);
  wide_particles[4000].id = wide_particles[17].id;
  const std::string wide = WriteRaw(dir_ / "wide.raw", wide_particles);
  const std::string wide_repeated = "ID " + std::to_string(wide_particles[17].id) + " is given to more than one";
  const std::string clean = WriteRaw(dir_ / "clean.raw", Clustered(6000, 32, 50.0));
  struct Case {
    std::vector<std::string> inputs;
    std::vector<std::string> message;
  };
  const Case cases[] = {{{dense}, {dense, repeated}},
                        {{wide}, {wide, wide_repeated}},
                        {{clean, dense}, {dense, repeated, "(1 repeats in all)", "--no-ids"}}};
  for (const Case& c : cases) {
    IngestOptions o = RawOptions(c.inputs, "store");
    o.neighbours = 0;
    SCOPED_TRACE(c.inputs.back());
    ExpectBadInputFrom([&] { Ingest(o); }, c.message);
    EXPECT_FALSE(fs::exists(o.output));
    EXPECT_TRUE(TempIsEmpty());
  }
  IngestOptions without = RawOptions({dense}, "without_ids");
  without.read.read_id = false;
  without.neighbours = 0;
  EXPECT_EQ(Ingest(without).input_points, particles.size());
  EXPECT_TRUE(VerifyStore(without.output).faults.empty());
}

// A periodic box that does not hold the particles (beyond 1% of it) stops
// the ingest before a store is made, naming the file, the box and a
// particle; --ignore-box takes the particles' bounds instead and --box-size
// the box given.
TEST_F(IngestTest, ParticlesOutsideThePeriodicBoxAreAnErrorUnlessTheBoxIsOverridden) {
  auto particles = Clustered(8000, 33, 100.0);
  particles[5000].x[0] = 150;
  const std::string input = WriteGadgetSet(dir_, "outside", particles, false);
  IngestOptions o = Options({input}, "store");
  o.tree.capacity = 500;
  ExpectBadInputFrom([&] { Ingest(o); }, {input + ".1", "lies at (150, ", "periodic box [0, 100)^3"});
  EXPECT_FALSE(fs::exists(o.output));
  EXPECT_TRUE(TempIsEmpty());

  IngestOptions ignoring = o;
  ignoring.read.ignore_box = true;
  Ingest(ignoring);
  const Dataset unboxed = Dataset::Open(ignoring.output);
  EXPECT_FALSE(unboxed.cube(0).periodic);
  EXPECT_EQ(CheckTree(unboxed, 0).leaf_points.size(), particles.size());

  IngestOptions boxed = o;
  boxed.output = (dir_ / "boxed").string();
  boxed.read.box_size_override = 200;
  Ingest(boxed);
  const Dataset big_box = Dataset::Open(boxed.output);
  EXPECT_TRUE(big_box.cube(0).periodic);
  EXPECT_EQ(big_box.cube(0).size, 200);
  EXPECT_EQ(CheckTree(big_box, 0).leaf_points.size(), particles.size());
}

// An epoch refused after others were written leaves no store behind, even
// in an output directory that was there before.
TEST_F(IngestTest, AnEpochRefusedLateLeavesNoStore) {
  const auto good = Clustered(5000, 34, 100.0);
  auto bad = Clustered(5000, 35, 100.0);
  bad[100].x[1] = -20;
  IngestOptions o = Options({WriteGadgetSet(dir_, "good", good, false), WriteGadgetSet(dir_, "bad", bad, false)}, "store");
  o.read.read_id = false;  // epochs one after the other: epoch 0 is written before epoch 1 is read
  o.neighbours = 0;
  fs::create_directories(o.output);
  ExpectBadInputFrom([&] { Ingest(o); }, {(dir_ / "bad.0").string(), "lies at ("});
  EXPECT_THROW(Dataset::Open(o.output), Error);
  EXPECT_TRUE(fs::is_empty(o.output)) << fs::directory_iterator(o.output)->path();
  EXPECT_TRUE(TempIsEmpty());
}

}  // namespace
}  // namespace octocosm
