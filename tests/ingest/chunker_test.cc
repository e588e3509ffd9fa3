// The out-of-core chunker (ingest/chunker.h) on its own: whatever its
// memory allows, every point lands in exactly one chunk that holds it, and the
// chunks are the same; what spilled to temporary files comes back intact and
// the files are gone once taken.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <numeric>
#include <random>

#include "ingest/chunker.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

const Cube kCube{{0, 0, 0}, 100, false};

// Half the points in a tight clump (so chunks must be split again), half
// spread over the cube; IDs 1..n, masses from the ID so they can be checked.
ParticleChunk Points(std::size_t n) {
  std::mt19937_64 rng(17);
  std::normal_distribution<double> clump(30, 0.5);
  std::uniform_real_distribution<double> anywhere(0, 100);
  ParticleChunk points;
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) points.position.push_back(i % 2 == 0 ? clump(rng) : anywhere(rng));
    points.mass.push_back(1.0 + static_cast<double>(i % 7));
    points.type.push_back(static_cast<std::uint8_t>(i % 3));
    points.id.push_back(i + 1);
  }
  return points;
}

// Feeds `points` in batches, as a snapshot reader would.
PointPass PassOver(const ParticleChunk& points, std::size_t batch_points) {
  return [&points, batch_points](const std::function<void(const ParticleChunk&)>& consume) {
    for (std::size_t begin = 0; begin < points.size(); begin += batch_points) {
      const std::size_t end = std::min(points.size(), begin + batch_points);
      ParticleChunk batch;
      batch.position.assign(points.position.begin() + 3 * begin, points.position.begin() + 3 * end);
      batch.mass.assign(points.mass.begin() + begin, points.mass.begin() + end);
      batch.type.assign(points.type.begin() + begin, points.type.begin() + end);
      batch.id.assign(points.id.begin() + begin, points.id.begin() + end);
      if (points.has_smoothing()) batch.smoothing.assign(points.smoothing.begin() + begin, points.smoothing.begin() + end);
      consume(batch);
    }
  };
}

struct Split {
  std::map<std::uint64_t, std::uint64_t> counts;          // chunk key -> points
  std::map<std::uint64_t, std::vector<std::uint64_t>> ids;  // chunk key -> its points' IDs, in chunk order
  std::uint64_t spilled = 0;
};

struct SplitSettings {
  std::size_t memory_bytes = std::size_t{1} << 30;
  int threads = 1;
  std::size_t batch_points = 1000;
};

// Splits `points` with `memory_bytes` of buffers, takes every chunk's points
// back and checks each one against the input: in its chunk's cell, with its
// own mass and type, and seen once.
Split SplitAndCheck(const ParticleChunk& points, const SplitSettings& settings, const fs::path& temp) {
  ChunkerOptions options;
  options.max_chunk_points = 3000;
  options.split_levels = 2;
  options.memory_bytes = settings.memory_bytes;
  options.threads = settings.threads;
  options.temp_dir = temp.string();
  options.columns.id = true;
  options.columns.smoothing = points.has_smoothing();
  Chunker chunker(kCube, options);
  std::vector<Chunk> chunks = chunker.Split(NodeKey::Root(), PassOver(points, settings.batch_points));
  Split split;
  split.spilled = chunker.spilled_points();
  std::vector<int> seen(points.size(), 0);
  for (Chunk& chunk : chunks) {
    const bool on_disk = !chunk.path.empty();
    const std::string path = chunk.path;
    const ParticleChunk taken = chunk.TakePoints();
    if (on_disk) {
      EXPECT_FALSE(fs::exists(path)) << "a taken chunk's file is removed";
    }
    EXPECT_EQ(taken.size(), chunk.point_count);
    EXPECT_TRUE(split.counts.emplace(chunk.key.value(), chunk.point_count).second) << "one chunk per key";
    split.ids[chunk.key.value()] = taken.id;
    EXPECT_TRUE(std::is_sorted(taken.id.begin(), taken.id.end())) << "chunk " << chunk.key.Path() << " keeps input order";
    for (std::size_t i = 0; i < taken.size(); ++i) {
      const std::uint64_t id = taken.id[i];
      EXPECT_TRUE(id >= 1 && id <= points.size());
      if (!(id >= 1 && id <= points.size())) continue;
      const std::size_t k = static_cast<std::size_t>(id - 1);
      ++seen[k];
      EXPECT_TRUE(kCube.Holds(chunk.key, &taken.position[3 * i])) << "ID " << id << " in chunk " << chunk.key.Path();
      for (int a = 0; a < 3; ++a) EXPECT_EQ(taken.position[3 * i + a], points.position[3 * k + a]);
      EXPECT_EQ(taken.mass[i], points.mass[k]);
      EXPECT_EQ(taken.type[i], points.type[k]);
      EXPECT_EQ(taken.has_smoothing(), points.has_smoothing());
      if (taken.has_smoothing() && points.has_smoothing()) {
        EXPECT_EQ(taken.smoothing[i], points.smoothing[k]) << "ID " << id;
      }
    }
  }
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), static_cast<std::ptrdiff_t>(points.size()))
      << "every point in exactly one chunk";
  return split;
}

// With buffers for the whole set nothing touches the disk; with buffers for
// a few hundred points most of it spills. Both give the same chunks (the
// clump split again below its first cell), every point intact in one of
// them, and no temporary file left behind.
TEST(Chunker, SpillingChangesNothingButWhereThePointsWait) {
  testing_support::TempDir dir("chunker-test");
  const ParticleChunk points = Points(40000);
  const fs::path in_memory = dir.path() / "in-memory", spilling = dir.path() / "spilling";
  fs::create_directories(in_memory);
  fs::create_directories(spilling);
  const Split held = SplitAndCheck(points, {.memory_bytes = std::size_t{1} << 30}, in_memory);
  const Split spilled = SplitAndCheck(points, {.memory_bytes = 16 << 10}, spilling);
  EXPECT_EQ(held.spilled, 0u);
  EXPECT_GT(spilled.spilled, points.size() / 2) << "a 16 KiB budget must spill most points";
  EXPECT_EQ(held.counts, spilled.counts);
  std::uint64_t deepest = 0;
  for (const auto& [key, count] : held.counts) {
    EXPECT_LE(count, 3000u) << NodeKey::FromValue(key).Path();
    deepest = std::max<std::uint64_t>(deepest, static_cast<std::uint64_t>(NodeKey::FromValue(key).level()));
  }
  EXPECT_GT(deepest, 2u) << "the clump's chunk must have been split again";
  EXPECT_TRUE(fs::is_empty(in_memory));
  EXPECT_TRUE(fs::is_empty(spilling)) << "no chunk file left once every chunk was taken";
}

// Many clumps, each a chunk that must be split again: the buffers that the
// first split and each re-split leave in memory add up, and spilling them
// keeps every buffer together within the budget (plus one batch of the pass),
// however many re-splits there are.
TEST(Chunker, BuffersOfAllSplitsTogetherStayWithinTheBudget) {
  testing_support::TempDir dir("chunker-test");
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> anywhere(0, 100);
  ParticleChunk points;
  for (int clump = 0; clump < 48; ++clump) {
    const double centre[3] = {anywhere(rng), anywhere(rng), anywhere(rng)};
    std::normal_distribution<double> spread(0, 0.2);
    for (int i = 0; i < 5000; ++i) {
      for (double c : centre) points.position.push_back(std::clamp(c + spread(rng), 0.0, 99.999));
    }
  }
  for (std::size_t i = 0; i < points.position.size() / 3; ++i) {
    points.mass.push_back(1);
    points.type.push_back(0);
    points.id.push_back(i + 1);
  }
  ChunkerOptions options;
  options.max_chunk_points = 3000;
  options.split_levels = 2;
  options.columns.id = true;
  constexpr std::size_t kBudgetPoints = 30000, kBatch = 1000;
  options.memory_bytes = kBudgetPoints * options.columns.BytesPerPoint();
  options.temp_dir = dir.path().string();
  Chunker chunker(kCube, options);
  std::vector<Chunk> chunks = chunker.Split(NodeKey::Root(), PassOver(points, kBatch));
  EXPECT_LE(chunker.peak_buffered_points(), kBudgetPoints + kBatch);
  EXPECT_GT(chunker.spilled_points(), 0u);
  std::uint64_t total = 0, in_memory = 0;
  for (Chunk& chunk : chunks) {
    in_memory += chunk.points.size();
    total += chunk.TakePoints().size();
  }
  EXPECT_EQ(total, points.size());
  EXPECT_LE(in_memory, kBudgetPoints);
}

// Smoothing lengths, when the points carry them, come back with their points
// from buffers and from spilled files alike.
TEST(Chunker, SmoothingLengthsTravelWithTheirPointsThroughSpilledFiles) {
  testing_support::TempDir dir("chunker-test");
  ParticleChunk points = Points(40000);
  for (const std::uint64_t id : points.id) points.smoothing.push_back(id % 5 == 0 ? 0.0f : 0.001f * static_cast<float>(id));
  const fs::path in_memory = dir.path() / "in-memory", spilling = dir.path() / "spilling";
  fs::create_directories(in_memory);
  fs::create_directories(spilling);
  const Split held = SplitAndCheck(points, {.memory_bytes = std::size_t{1} << 30}, in_memory);
  const Split spilled = SplitAndCheck(points, {.memory_bytes = 16 << 10}, spilling);
  EXPECT_GT(spilled.spilled, points.size() / 2) << "a 16 KiB budget must spill most points";
  EXPECT_EQ(held.ids, spilled.ids);
  EXPECT_TRUE(fs::is_empty(spilling));
}

// Points are placed, gathered and spilled on several threads, each gathering
// the points of its own cells: the chunks hold the same points in the same
// order (which the tree builder does not need, but a reader of the chunks
// might) for any thread count, in memory or spilling. Batches are large
// enough here for the work to be shared out.
TEST(Chunker, ThreadsChangeNothing) {
  testing_support::TempDir dir("chunker-threads-test");
  const ParticleChunk points = Points(100000);
  for (const std::size_t memory : {std::size_t{1} << 30, std::size_t{64} << 10}) {
    SCOPED_TRACE("memory " + std::to_string(memory));
    const fs::path one = dir.path() / ("one-" + std::to_string(memory));
    const fs::path three = dir.path() / ("three-" + std::to_string(memory));
    fs::create_directories(one);
    fs::create_directories(three);
    const Split single = SplitAndCheck(points, {.memory_bytes = memory, .threads = 1, .batch_points = 40000}, one);
    const Split shared = SplitAndCheck(points, {.memory_bytes = memory, .threads = 3, .batch_points = 40000}, three);
    EXPECT_EQ(single.spilled, shared.spilled);
    EXPECT_EQ(single.ids, shared.ids);
    EXPECT_TRUE(fs::is_empty(one));
    EXPECT_TRUE(fs::is_empty(three));
  }
}

// Splits `points` held in memory whole and as a stream of batches, with
// `options`, and checks that the chunks are the same, each listing (as
// indices into the held set, which stays in input order) the same points in
// the same order, and that nothing touched the disk; and that the held set
// kept its positions as floats when `held_as_floats` says so.
void ExpectResidentSplitLikeStreamed(const ParticleChunk& points, const ChunkerOptions& options, bool held_as_floats,
                                     const fs::path& temp) {
  Chunker streaming(kCube, options);
  std::vector<Chunk> streamed = streaming.Split(NodeKey::Root(), PassOver(points, 7000));
  Chunker in_place(kCube, options);
  ResidentEpoch held;
  held.Read(PassOver(points, 7000), 1000, options.columns);
  const std::vector<Chunk> chunks = in_place.SplitResident(NodeKey::Root(), held);
  ASSERT_EQ(held.size(), points.size()) << "an expected count too small only costs reallocations";
  EXPECT_EQ(held.positions_narrow(), held_as_floats);
  std::vector<std::uint32_t> every(held.size());
  std::iota(every.begin(), every.end(), 0u);
  ParticleChunk resident;
  held.CopyPoints(every, every, resident);
  EXPECT_EQ(resident.id, points.id) << "the resident set stays in input order";
  EXPECT_EQ(resident.position, points.position);
  ASSERT_EQ(chunks.size(), streamed.size());
  std::vector<int> listed(points.size(), 0);
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    EXPECT_EQ(chunks[c].key, streamed[c].key);
    EXPECT_EQ(chunks[c].point_count, streamed[c].point_count);
    EXPECT_TRUE(chunks[c].path.empty());
    EXPECT_EQ(chunks[c].points.size(), 0u);
    ASSERT_EQ(chunks[c].resident.size(), chunks[c].point_count);
    if (options.leaf_capacity == 0) {  // a merged chunk lists its parts one after another
      EXPECT_TRUE(std::adjacent_find(chunks[c].resident.begin(), chunks[c].resident.end(), std::greater_equal<>()) ==
                  chunks[c].resident.end())
          << "chunk " << chunks[c].key.Path() << " lists its points in input order";
    }
    const ParticleChunk taken = streamed[c].TakePoints();
    ASSERT_EQ(taken.size(), chunks[c].resident.size());
    for (std::size_t k = 0; k < taken.size(); ++k) {
      const std::uint32_t i = chunks[c].resident[k];
      ASSERT_LT(i, resident.size());
      ++listed[i];
      ASSERT_EQ(resident.id[i], taken.id[k]) << "chunk " << chunks[c].key.Path() << ", point " << k;
      EXPECT_EQ(resident.mass[i], taken.mass[k]);
      EXPECT_EQ(resident.type[i], taken.type[k]);
      for (int a = 0; a < 3; ++a) EXPECT_EQ(resident.position[3 * i + a], taken.position[3 * k + a]);
    }
  }
  EXPECT_EQ(std::count(listed.begin(), listed.end(), 1), static_cast<std::ptrdiff_t>(points.size()))
      << "every point listed once";
  EXPECT_EQ(in_place.spilled_points(), 0u);
  EXPECT_TRUE(fs::is_empty(temp));
}

ChunkerOptions ResidentTestOptions(const fs::path& temp) {
  ChunkerOptions options;
  options.max_chunk_points = 3000;
  options.split_levels = 2;
  options.memory_bytes = std::size_t{1} << 30;
  options.temp_dir = temp.string();
  options.columns.id = true;
  return options;
}

// A point set held in memory whole is cut into the same chunks as a stream
// of batches, whether the chunks under a leaf-sized node are merged or not,
// for any thread count, whether its positions are held as floats, and
// whether the first cut is shallow enough for 16-bit cell codes (two
// levels) or not (four).
TEST(Chunker, ResidentSplitCutsTheSameChunks) {
  testing_support::TempDir dir("chunker-resident-test");
  const ParticleChunk double_points = Points(60000);
  ParticleChunk float_points = Points(60000);  // positions a resident epoch keeps as floats
  for (double& x : float_points.position) x = static_cast<float>(x);
  for (const bool float_positions : {false, true}) {
    const ParticleChunk& points = float_positions ? float_points : double_points;
    for (const std::uint64_t leaf_capacity : {std::uint64_t{0}, std::uint64_t{700}}) {
      for (const int threads : {1, 3}) {
        for (const int split_levels : {2, 4}) {
          SCOPED_TRACE("leaf capacity " + std::to_string(leaf_capacity) + ", threads " + std::to_string(threads) +
                       ", split levels " + std::to_string(split_levels) + (float_positions ? ", float positions" : ""));
          ChunkerOptions options = ResidentTestOptions(dir.path());
          options.leaf_capacity = leaf_capacity;
          options.threads = threads;
          options.split_levels = split_levels;
          ExpectResidentSplitLikeStreamed(points, options, float_positions, dir.path());
        }
      }
    }
  }
}

// The resident split reads each point's cell down to five or ten levels
// below the region from codes computed once; a clump denser than a chunk
// within one such cell is split further from its positions, into the same
// chunks as a stream's.
TEST(Chunker, ResidentSplitGoesBelowItsPrecomputedCells) {
  testing_support::TempDir dir("chunker-resident-deep-test");
  ParticleChunk points = Points(20000);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> speck(61.3, 1e-4);  // 100 / 2^10 is ~0.1: deep inside one such cell
  for (std::size_t i = 0; i < points.size(); i += 2) {
    for (int a = 0; a < 3; ++a) points.position[3 * i + a] = speck(rng);
  }
  for (const int threads : {1, 3}) {
    for (const int split_levels : {2, 4}) {
      SCOPED_TRACE("threads " + std::to_string(threads) + ", split levels " + std::to_string(split_levels));
      ChunkerOptions options = ResidentTestOptions(dir.path());
      options.threads = threads;
      options.split_levels = split_levels;
      ExpectResidentSplitLikeStreamed(points, options, /*held_as_floats=*/false, dir.path());
      Chunker chunker(kCube, options);
      ResidentEpoch held;
      held.Read(PassOver(points, 7000), 0, options.columns);
      const std::vector<Chunk> chunks = chunker.SplitResident(NodeKey::Root(), held);
      int deepest = 0;
      for (const Chunk& chunk : chunks) {
        EXPECT_LE(chunk.point_count, options.max_chunk_points) << chunk.key.Path();
        deepest = std::max(deepest, chunk.key.level());
      }
      EXPECT_GT(deepest, 10) << "the speck is split below the precomputed cells";
    }
  }
}

// The end of the list cut finer: the last `window` chunks are each at most
// `most` points, or a leaf, while the chunks before them stay as they were;
// every point is still listed once, in a chunk that holds it, and the
// chunks still follow each other in depth-first order without overlapping.
TEST(Chunker, TailSplitLeavesOnlySmallChunksAtTheEnd) {
  testing_support::TempDir dir("chunker-tail-test");
  const ParticleChunk points = Points(60000);
  ChunkerOptions options = ResidentTestOptions(dir.path());
  options.leaf_capacity = 100;
  Chunker chunker(kCube, options);
  ResidentEpoch held;
  held.Read(PassOver(points, 7000), 0, options.columns);
  const std::vector<Chunk> whole = chunker.SplitResident(NodeKey::Root(), held);
  std::vector<std::pair<NodeKey, std::vector<std::uint32_t>>> before;
  for (const Chunk& chunk : whole) before.push_back({chunk.key, {chunk.resident.begin(), chunk.resident.end()}});
  constexpr std::size_t kWindow = 6;
  constexpr std::uint64_t kMost = 400;
  std::uint64_t largest_at_end = 0;
  for (std::size_t c = whole.size() - kWindow; c < whole.size(); ++c) {
    largest_at_end = std::max(largest_at_end, whole[c].point_count);
  }
  ASSERT_GT(largest_at_end, kMost) << "the test needs a large chunk at the end";

  const std::vector<Chunk> chunks = chunker.SplitTail(whole, held, kWindow, kMost);
  ASSERT_GT(chunks.size(), whole.size());
  for (std::size_t c = chunks.size() - kWindow; c < chunks.size(); ++c) {
    EXPECT_TRUE(chunks[c].point_count <= kMost || chunks[c].point_count <= options.leaf_capacity)
        << chunks[c].key.Path() << " holds " << chunks[c].point_count;
  }
  std::size_t unchanged = 0;
  while (unchanged < before.size() && chunks[unchanged].key == before[unchanged].first &&
         std::equal(chunks[unchanged].resident.begin(), chunks[unchanged].resident.end(),
                    before[unchanged].second.begin(), before[unchanged].second.end())) {
    ++unchanged;
  }
  EXPECT_GE(unchanged + kWindow, before.size()) << "only chunks in the tail are cut";
  std::vector<int> listed(points.size(), 0);
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    if (c > 0) {
      EXPECT_TRUE(PreorderLess{}(chunks[c - 1].key, chunks[c].key)) << c;
      EXPECT_FALSE(chunks[c - 1].key.IsAncestorOrSelf(chunks[c].key)) << c;
    }
    ASSERT_EQ(chunks[c].resident.size(), chunks[c].point_count);
    for (const std::uint32_t i : chunks[c].resident) {
      ASSERT_LT(i, points.size());
      ++listed[i];
      EXPECT_TRUE(kCube.Holds(chunks[c].key, &points.position[3 * std::size_t{i}])) << chunks[c].key.Path();
    }
  }
  EXPECT_EQ(std::count(listed.begin(), listed.end(), 1), static_cast<std::ptrdiff_t>(points.size()))
      << "every point listed once";

  // Asked for chunks smaller than a leaf, it cuts only chunks the tree makes
  // inner nodes (more than leaf_capacity points): cutting a leaf's chunk
  // would make the merger sample it from children, another tree.
  std::map<std::uint64_t, std::uint64_t> whole_counts;
  for (const Chunk& chunk : whole) whole_counts[chunk.key.value()] = chunk.point_count;
  const std::vector<Chunk> fine = chunker.SplitTail(whole, held, kWindow, options.leaf_capacity / 4);
  for (const Chunk& chunk : fine) {
    if (whole_counts.count(chunk.key.value()) != 0) continue;
    // A new chunk's parent was a chunk once, cut: it must have held more
    // than a leaf does.
    const NodeKey cut = chunk.key.AncestorAt(chunk.key.level() - 1);
    std::uint64_t under_cut = 0;
    for (const Chunk& other : fine) under_cut += cut.IsAncestorOrSelf(other.key) ? other.point_count : 0;
    EXPECT_GT(under_cut, options.leaf_capacity) << "the leaf-sized chunk " << cut.Path() << " was cut";
  }
  for (std::size_t c = fine.size() - kWindow; c < fine.size(); ++c) {
    EXPECT_LE(fine[c].point_count, options.leaf_capacity) << fine[c].key.Path();
  }
}

}  // namespace
}  // namespace octocosm
