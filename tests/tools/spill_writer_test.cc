// The chunker's background spill writer: files hold the batches in submission
// order, errors on its thread reach the caller as the same Error, and a
// chunker that spills through it cuts the same chunks as one that never
// spills.
#include "tools/ingest/spill_writer.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <functional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "storage/error.h"
#include "tools/ingest/chunker.h"
#include "tools/ingest/particle_file.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

// `n` points in the unit cube with IDs first_id, first_id + 1, ...
ParticleChunk Points(std::size_t n, std::uint64_t first_id, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(0, 1);
  ParticleChunk chunk;
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) chunk.position.push_back(uniform(rng));
    chunk.mass.push_back(1.0 + static_cast<double>(i % 5));
    chunk.type.push_back(static_cast<std::uint8_t>(i % 3));
    chunk.id.push_back(first_id + i);
  }
  return chunk;
}

ParticleColumns WithIds() {
  ParticleColumns columns;
  columns.id = true;
  return columns;
}

std::vector<std::uint64_t> IdsInFile(const std::string& path) {
  ParticleChunk all;
  ParticleFileReader(path).ReadAll(all);
  return all.id;
}

class SpillWriterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocosm-spill-writer-test-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(SpillWriterTest, FilesHoldTheBatchesInSubmissionOrder) {
  const std::string a = (dir_ / "a.pts").string(), b = (dir_ / "b.pts").string();
  ParticleFileWriter file_a(a, WithIds()), file_b(b, WithIds());
  std::vector<std::uint64_t> expected_a, expected_b;
  {
    SpillWriter writer;
    for (std::uint64_t batch = 0; batch < 40; ++batch) {
      const bool to_a = batch % 3 != 0;
      ParticleChunk points = Points(100 + batch, batch * 1000, batch);
      (to_a ? expected_a : expected_b).insert((to_a ? expected_a : expected_b).end(), points.id.begin(), points.id.end());
      writer.Submit(to_a ? file_a : file_b, std::move(points));
      if (batch % 7 == 0) writer.WaitForPendingAtMost(150);
    }
    writer.Drain();
    EXPECT_EQ(writer.pending_points(), 0u);
  }
  file_a.Close();
  file_b.Close();
  EXPECT_EQ(IdsInFile(a), expected_a);
  EXPECT_EQ(IdsInFile(b), expected_b);
}

TEST_F(SpillWriterTest, AFullDiskSurfacesAsTheSameIoErrorAtTheCaller) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  ParticleFileWriter full("/dev/full", WithIds());
  SpillWriter writer;
  writer.Submit(full, Points(100000, 0, 1));  // larger than the stdio buffer: written at once
  writer.Submit(full, Points(10, 0, 2));
  try {
    writer.Drain();
    FAIL() << "writing to /dev/full must fail";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kIo) << e.what();
    EXPECT_NE(std::string(e.what()).find("/dev/full"), std::string::npos) << e.what();
  }
  EXPECT_EQ(writer.pending_points(), 0u);  // the batch after the error was dropped
  EXPECT_THROW(writer.Submit(full, Points(10, 0, 3)), Error);
}

TEST_F(SpillWriterTest, DestroyingWithBatchesQueuedNeitherWritesThemAllNorHangs) {
  const std::string path = (dir_ / "c.pts").string();
  ParticleFileWriter file(path, WithIds());
  {
    SpillWriter writer;
    for (int batch = 0; batch < 50; ++batch) writer.Submit(file, Points(20000, 0, 4));
  }  // the caller unwinding after an error of its own
  file.Close();
  EXPECT_LE(IdsInFile(path).size(), std::size_t{50} * 20000);
}

// A chunker whose buffers hold a few hundred points spills nearly everything
// through the writer, yet cuts the same chunks, each with its points in input
// order, as one that keeps everything in memory.
TEST_F(SpillWriterTest, ChunkerSpillingThroughItCutsTheSameChunks) {
  const Cube cube{{0, 0, 0}, 1.0, false};
  std::vector<ParticleChunk> batches;
  for (std::uint64_t b = 0; b < 20; ++b) batches.push_back(Points(1000, b * 1000, 10 + b));
  const PointPass pass = [&](const std::function<void(const ParticleChunk&)>& consume) {
    for (const ParticleChunk& batch : batches) consume(batch);
  };
  auto split = [&](std::size_t memory_bytes, std::uint64_t& spilled) {
    ChunkerOptions options;
    options.max_chunk_points = 600;  // some cells are split again from their files
    options.split_levels = 1;
    options.memory_bytes = memory_bytes;
    options.temp_dir = dir_.string();
    options.columns = WithIds();
    Chunker chunker(cube, options);
    std::vector<Chunk> chunks = chunker.Split(NodeKey::Root(), pass);
    spilled = chunker.spilled_points();
    std::vector<std::pair<std::uint64_t, std::vector<std::uint64_t>>> ids;
    for (Chunk& chunk : chunks) ids.emplace_back(chunk.key.value(), chunk.TakePoints().id);
    return ids;
  };
  std::uint64_t spilled_in_memory = 0, spilled_small = 0;
  const auto in_memory = split(std::size_t{1} << 30, spilled_in_memory);
  const auto small = split(300 * WithIds().BytesPerPoint(), spilled_small);
  EXPECT_EQ(spilled_in_memory, 0u);
  EXPECT_GT(spilled_small, 15000u);
  EXPECT_GT(in_memory.size(), 8u);
  EXPECT_EQ(in_memory, small);
  std::size_t points = 0;
  for (const auto& chunk : in_memory) points += chunk.second.size();
  EXPECT_EQ(points, 20000u);
  EXPECT_TRUE(fs::is_empty(dir_));  // every chunk file was consumed
}

}  // namespace
}  // namespace octocosm
