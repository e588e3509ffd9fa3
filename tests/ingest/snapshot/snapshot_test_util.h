// Helpers shared by the snapshot reader tests: draining a source into one
// big batch, expecting a clean BadInput error, and a scratch directory that cleans up after itself.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "base/error.h"
#include "index/particle_chunk.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

// Concatenates every chunk of `source` (from where it stands to the end),
// checking the per-chunk invariants on the way.
inline ParticleChunk ReadAll(ParticleSource& source, std::size_t* chunks = nullptr) {
  ParticleChunk all, chunk;
  std::size_t count = 0;
  while (source.Next(chunk)) {
    ++count;
    EXPECT_GT(chunk.size(), 0u);
    EXPECT_EQ(chunk.position.size(), 3 * chunk.size());
    EXPECT_EQ(chunk.type.size(), chunk.size());
    EXPECT_EQ(chunk.has_velocity(), source.header().has_velocity);
    EXPECT_EQ(chunk.has_id(), source.header().has_id);
    EXPECT_EQ(chunk.has_smoothing(), source.header().has_smoothing);
    if (chunk.has_smoothing()) {
      EXPECT_EQ(chunk.smoothing.size(), chunk.size());
    }
    if (chunk.has_velocity()) {
      EXPECT_EQ(chunk.velocity.size(), 3 * chunk.size());
    }
    if (chunk.has_id()) {
      EXPECT_EQ(chunk.id.size(), chunk.size());
    }
    all.Append(chunk);
  }
  EXPECT_EQ(chunk.size(), 0u) << "Next() returning false must leave the chunk empty";
  if (chunks != nullptr) *chunks = count;
  return all;
}

// Expects OpenSnapshot + reading everything to fail with BadInput whose
// message names `path` and contains `problem`.
inline void ExpectBadInput(const std::string& path, const std::string& problem, const ReadOptions& options = {}) {
  try {
    auto source = OpenSnapshot(path, options);
    ReadAll(*source);
    ADD_FAILURE() << "no error for " << path << " (expected \"" << problem << "\")";
  } catch (const Error& error) {
    EXPECT_EQ(error.kind(), ErrorKind::kBadInput) << error.what();
    EXPECT_NE(std::string(error.what()).find(path), std::string::npos) << error.what();
    EXPECT_NE(std::string(error.what()).find(problem), std::string::npos) << error.what();
  }
}

// Skip() passes over exactly the batch Next() would hand out: a pass that
// skips every other batch reads the others as a pass of Next() alone does.
// `open` opens the same snapshot afresh.
template <typename Open>
void ExpectSkipPassesOverNextsBatches(const Open& open) {
  auto plain = open();
  std::vector<ParticleChunk> batches;
  for (ParticleChunk chunk; plain->Next(chunk);) batches.push_back(chunk);
  ASSERT_GT(batches.size(), 3u) << "too few batches to tell";
  for (std::size_t first : {0, 1}) {
    auto skipping = open();
    std::size_t b = 0;
    for (;; ++b) {
      if (b % 2 != first) {
        const std::uint64_t skipped = skipping->Skip();
        if (skipped == 0) break;
        ASSERT_LT(b, batches.size());
        EXPECT_EQ(skipped, batches[b].size()) << "batch " << b;
        continue;
      }
      ParticleChunk chunk;
      if (!skipping->Next(chunk)) break;
      ASSERT_LT(b, batches.size());
      EXPECT_EQ(chunk.position, batches[b].position) << "batch " << b;
      EXPECT_EQ(chunk.id, batches[b].id) << "batch " << b;
      EXPECT_EQ(chunk.mass, batches[b].mass) << "batch " << b;
    }
    EXPECT_EQ(b, batches.size());
  }
}

inline bool SameParticles(const ParticleChunk& a, const ParticleChunk& b) {
  return a.position == b.position && a.velocity == b.velocity && a.mass == b.mass && a.id == b.id &&
         a.type == b.type && a.smoothing == b.smoothing;
}

class ScratchDir {
 public:
  ScratchDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = std::filesystem::temp_directory_path() /
            ("octocosm_snapshot_" + std::string(info->test_suite_name()) + "_" + info->name() + "_" +
             std::to_string(::getpid()));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~ScratchDir() { std::filesystem::remove_all(path_); }
  std::string File(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

}  // namespace octocosm
