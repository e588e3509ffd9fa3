// Temporary particle files: batches of every column come back exactly, across
// the files' 1 MiB buffers, from writers that take turns on threads; the file
// is as long as what was written; a short or stray file is corruption naming
// it.
#include "ingest/particle_file.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "base/error.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

ParticleChunk RandomChunk(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<double> uniform(-1e6, 1e6);
  ParticleChunk chunk;
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) chunk.position.push_back(uniform(random));
    chunk.mass.push_back(uniform(random));
    chunk.id.push_back(random());
    chunk.type.push_back(static_cast<std::uint8_t>(random() % 6));
    chunk.smoothing.push_back(static_cast<float>(uniform(random)));
    for (int a = 0; a < 3; ++a) {
      chunk.velocity.push_back(static_cast<float>(uniform(random)));
      chunk.displacement.push_back(static_cast<float>(uniform(random)));
    }
  }
  return chunk;
}

ParticleColumns AllColumnsOf(const ParticleChunk&) {
  ParticleColumns columns;
  columns.id = true;
  columns.smoothing = true;
  columns.vector(VectorColumn::kVelocity) = true;
  columns.vector(VectorColumn::kDisplacement) = true;
  return columns;
}

void ExpectSame(const ParticleChunk& got, const ParticleChunk& want) {
  EXPECT_EQ(got.position, want.position);
  EXPECT_EQ(got.mass, want.mass);
  EXPECT_EQ(got.id, want.id);
  EXPECT_EQ(got.type, want.type);
  EXPECT_EQ(got.smoothing, want.smoothing);
  EXPECT_EQ(got.velocity, want.velocity);
  EXPECT_EQ(got.displacement, want.displacement);
}

TEST(ParticleFile, BatchesOfEverySizeComeBackExactly) {
  testing_support::TempDir dir("particle-file");
  const std::string path = (dir.path() / "chunk.particles").string();
  // 1, an odd few, and enough for several buffers in one batch.
  const std::vector<std::size_t> sizes = {1, 7, 40000, 3, 123457, 1};
  std::vector<ParticleChunk> batches;
  ParticleChunk all;
  ParticleFileWriter writer(path, AllColumnsOf(all));
  std::uint64_t bytes = 16;  // magic and flags
  for (std::size_t b = 0; b < sizes.size(); ++b) {
    batches.push_back(RandomChunk(sizes[b], b + 1));
    writer.Append(batches.back());
    bytes += 9 + sizes[b] * AllColumnsOf(all).BytesPerPoint();  // random values: nothing narrows
  }
  writer.Close();
  EXPECT_EQ(std::filesystem::file_size(path), bytes);  // no padding left behind

  ParticleFileReader reader(path);
  EXPECT_TRUE(reader.columns().id);
  EXPECT_TRUE(reader.columns().vector(VectorColumn::kDisplacement));
  EXPECT_FALSE(reader.columns().vector(VectorColumn::kNextVelocity));
  ParticleChunk chunk;
  for (const ParticleChunk& want : batches) {
    ASSERT_TRUE(reader.Next(chunk));
    ExpectSame(chunk, want);
  }
  EXPECT_FALSE(reader.Next(chunk));

  ParticleFileReader again(path);
  ParticleChunk whole;
  again.ReadAll(whole);
  EXPECT_EQ(whole.size(), 40000u + 123457u + 12u);
  EXPECT_EQ(whole.id.back(), batches.back().id.back());
}

// A snapshot's dark matter: float positions, one mass, one type, IDs below
// 2^32 in a batch of 50000.
ParticleChunk DarkMatterChunk() {
  std::mt19937_64 random(5);
  std::uniform_real_distribution<float> uniform(0.0f, 1e5f);
  ParticleChunk chunk;
  for (std::size_t i = 0; i < 50000; ++i) {
    for (int a = 0; a < 3; ++a) chunk.position.push_back(uniform(random));
    chunk.mass.push_back(0.0123);
    chunk.id.push_back(random() >> 32);
    chunk.type.push_back(1);
  }
  return chunk;
}

TEST(ParticleFile, BatchesAsNarrowAsTheirValuesAllowComeBackExactly) {
  testing_support::TempDir dir("particle-file");
  const std::string path = (dir.path() / "chunk.particles").string();
  ParticleColumns columns;
  columns.id = true;
  const std::size_t n = DarkMatterChunk().size();
  // Each change breaks one narrowing, at the batch's last point.
  struct Case {
    const char* what;
    bool float_positions, one_mass, one_type, narrow_ids;
    void (*change)(ParticleChunk&);
  };
  const Case cases[] = {
      {"all narrow", true, true, true, true, [](ParticleChunk&) {}},
      {"a coordinate that is no float", false, true, true, true, [](ParticleChunk& c) { c.position.back() += 1e-9; }},
      {"a coordinate beyond the float range", false, true, true, true, [](ParticleChunk& c) { c.position.back() = 1e300; }},
      {"a mass of -0", true, false, true, true,
       [](ParticleChunk& c) {
         c.mass.assign(c.mass.size(), 0.0);
         c.mass.back() = -0.0;
       }},
      {"another type", true, true, false, true, [](ParticleChunk& c) { c.type.back() = 4; }},
      {"an ID of 2^32", true, true, true, false, [](ParticleChunk& c) { c.id.back() = std::uint64_t{1} << 32; }},
  };
  for (const Case& c : cases) {
    ParticleChunk chunk = DarkMatterChunk();
    c.change(chunk);
    ParticleFileWriter writer(path, columns);
    writer.Append(chunk);
    writer.Append(chunk, 7, 8);  // a batch of one point is narrow in every way
    writer.Close();
    const std::uint64_t batch = 8 + 1 + n * (c.float_positions ? 12 : 24) + (c.one_mass ? 8 : 8 * n) +
                                (c.one_type ? 1 : n) + n * (c.narrow_ids ? 4 : 8);
    const std::uint64_t one_point_batch = 8 + 1 + 12 + 8 + 1 + 4;
    EXPECT_EQ(std::filesystem::file_size(path), 16 + batch + one_point_batch) << c.what;
    ParticleFileReader reader(path);
    ParticleChunk got;
    ASSERT_TRUE(reader.Next(got)) << c.what;
    ExpectSame(got, chunk);
    EXPECT_TRUE(std::signbit(got.mass.back()) == std::signbit(chunk.mass.back())) << c.what;
    ASSERT_TRUE(reader.Next(got)) << c.what;
    ASSERT_EQ(got.size(), 1u);
    EXPECT_EQ(got.id[0], chunk.id[7]);
    EXPECT_EQ(got.position[2], chunk.position[23]);
    EXPECT_FALSE(reader.Next(got));
  }
}

TEST(ParticleFile, WritersTakingTurnsOnThreadsKeepTheirOwnBytes) {
  // A chunker appends to many files in turn, from several threads.
  testing_support::TempDir dir("particle-file");
  constexpr int kFiles = 5;
  std::vector<std::string> paths;
  std::vector<ParticleFileWriter> writers;
  std::vector<ParticleChunk> written(kFiles);
  const ParticleColumns columns = AllColumnsOf(written[0]);
  for (int f = 0; f < kFiles; ++f) {
    paths.push_back((dir.path() / ("chunk" + std::to_string(f))).string());
    writers.emplace_back(paths.back(), columns);
  }
  for (int round = 0; round < 6; ++round) {
    std::vector<std::thread> threads;
    for (int t = 0; t < 2; ++t) {
      threads.emplace_back([&, t] {
        for (int f = t; f < kFiles; f += 2) {
          const ParticleChunk batch = RandomChunk(static_cast<std::size_t>(1 + (round * 7919 + f * 104729) % 30000),
                                                  static_cast<std::uint64_t>(round * kFiles + f));
          writers[f].Append(batch);
          written[f].Append(batch);
        }
      });
    }
    for (std::thread& thread : threads) thread.join();
  }
  for (int f = 0; f < kFiles; ++f) {
    writers[f].Close();
    ParticleFileReader reader(paths[f]);
    ParticleChunk got;
    reader.ReadAll(got);
    ExpectSame(got, written[f]);
  }
}

TEST(ParticleFile, AShortOrStrayFileIsCorruptionNamingIt) {
  testing_support::TempDir dir("particle-file");
  const std::string path = (dir.path() / "chunk.particles").string();
  const ParticleChunk chunk = RandomChunk(50000, 9);
  {
    ParticleFileWriter writer(path, AllColumnsOf(chunk));
    writer.Append(chunk);
    writer.Close();
  }
  for (std::uint64_t cut : {std::uint64_t{20}, std::uint64_t{4096}, std::uint64_t{1} << 20,
                            std::filesystem::file_size(path) - 1}) {
    std::filesystem::resize_file(path, cut);
    try {
      ParticleFileReader reader(path);
      ParticleChunk got;
      reader.Next(got);
      ADD_FAILURE() << "a file cut to " << cut << " bytes was read";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kCorruption) << e.what();
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  }
  {
    std::ofstream stray(path, std::ios::binary | std::ios::trunc);
    stray << "not a particle file at all";
  }
  try {
    ParticleFileReader reader(path);
    ADD_FAILURE() << "a stray file was opened";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kCorruption);
    EXPECT_NE(std::string(e.what()).find("wrong magic"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace octocosm
