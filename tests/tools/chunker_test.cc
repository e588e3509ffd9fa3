// The out-of-core chunker (tools/ingest/chunker.h) on its own: whatever its
// memory allows, every point lands in exactly one chunk that holds it, and the
// chunks are the same; what spilled to temporary files comes back intact and
// the files are gone once taken.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <random>

#include "tests/support/temp_dir.h"
#include "tools/ingest/chunker.h"

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

// Feeds `points` in batches of 1000, as a snapshot reader would.
PointPass PassOver(const ParticleChunk& points) {
  return [&points](const std::function<void(const ParticleChunk&)>& consume) {
    for (std::size_t begin = 0; begin < points.size(); begin += 1000) {
      const std::size_t end = std::min(points.size(), begin + 1000);
      ParticleChunk batch;
      batch.position.assign(points.position.begin() + 3 * begin, points.position.begin() + 3 * end);
      batch.mass.assign(points.mass.begin() + begin, points.mass.begin() + end);
      batch.type.assign(points.type.begin() + begin, points.type.begin() + end);
      batch.id.assign(points.id.begin() + begin, points.id.begin() + end);
      consume(batch);
    }
  };
}

struct Split {
  std::map<std::uint64_t, std::uint64_t> counts;  // chunk key -> points
  std::uint64_t spilled = 0;
};

// Splits `points` with `memory_bytes` of buffers, takes every chunk's points
// back and checks each one against the input: in its chunk's cell, with its
// own mass and type, and seen once.
Split SplitAndCheck(const ParticleChunk& points, std::size_t memory_bytes, const fs::path& temp) {
  ChunkerOptions options;
  options.max_chunk_points = 3000;
  options.split_levels = 2;
  options.memory_bytes = memory_bytes;
  options.temp_dir = temp.string();
  options.columns.id = true;
  Chunker chunker(kCube, options);
  std::vector<Chunk> chunks = chunker.Split(NodeKey::Root(), PassOver(points));
  Split split;
  split.spilled = chunker.spilled_points();
  std::vector<int> seen(points.size(), 0);
  for (Chunk& chunk : chunks) {
    const bool on_disk = !chunk.path.empty();
    const std::string path = chunk.path;
    const ParticleChunk taken = chunk.TakePoints();
    if (on_disk) EXPECT_FALSE(fs::exists(path)) << "a taken chunk's file is removed";
    EXPECT_EQ(taken.size(), chunk.point_count);
    EXPECT_TRUE(split.counts.emplace(chunk.key.value(), chunk.point_count).second) << "one chunk per key";
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
  const Split held = SplitAndCheck(points, std::size_t{1} << 30, in_memory);
  const Split spilled = SplitAndCheck(points, 16 << 10, spilling);
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

}  // namespace
}  // namespace octocosm
