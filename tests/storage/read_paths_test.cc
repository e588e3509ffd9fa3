// The read paths beside ReadBlock: ranged reads of part of a block, reads
// into a reused buffer, and the cache's recycling of evicted buffers.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <random>

#include "base/error.h"
#include "storage/block_cache.h"
#include "storage/store_reader.h"
#include "storage/store_writer.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

class ReadPathsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocosm-read-paths-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    std::mt19937_64 rng(5);
    StoreWriterOptions options;
    options.page_size = 4096;
    StoreWriter writer(dir_.string(), nlohmann::json::object(), nlohmann::json::object(), options);
    writer.BeginEpoch(0, 0);
    for (std::uint64_t key = 1; key <= 40; ++key) {
      Bytes block(rng() % 20000);
      for (auto& b : block) b = static_cast<std::uint8_t>(rng());
      writer.AddBlock(key, block, 0);
      blocks_.push_back(std::move(block));
    }
    writer.EndEpoch();
    writer.Finish();
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path dir_;
  std::vector<Bytes> blocks_;  // blocks_[key - 1]
};

TEST_F(ReadPathsTest, RangedReadsReturnTheBytesOfThatRangeAndRefuseToOverrun) {
  const StoreReader store = StoreReader::Open(dir_.string());
  std::mt19937_64 rng(6);
  for (int trial = 0; trial < 500; ++trial) {
    const std::uint64_t key = 1 + rng() % blocks_.size();
    const Bytes& block = blocks_[key - 1];
    const std::size_t offset = block.empty() ? 0 : rng() % block.size();
    const std::size_t length = block.size() == offset ? 0 : rng() % (block.size() - offset + 1);
    Bytes out(length);
    store.ReadBlockRange({0, key}, offset, out);
    ASSERT_TRUE(std::equal(out.begin(), out.end(), block.begin() + static_cast<std::ptrdiff_t>(offset)));
  }
  Bytes one(1);
  EXPECT_THROW(store.ReadBlockRange({0, 1}, blocks_[0].size(), one), Error);
  EXPECT_THROW(store.ReadBlockRange({0, 999}, 0, one), Error);
}

TEST_F(ReadPathsTest, ReadIntoABufferReusesItsCapacity) {
  const StoreReader store = StoreReader::Open(dir_.string());
  Bytes buffer;
  buffer.reserve(1 << 16);
  const auto* data = buffer.data();
  for (std::uint64_t key = 1; key <= blocks_.size(); ++key) {
    store.ReadBlock({0, key}, buffer);
    ASSERT_EQ(buffer, blocks_[key - 1]);
    ASSERT_EQ(buffer.data(), data) << "no reallocation while the capacity suffices";
  }
}

TEST_F(ReadPathsTest, RecycledBuffersNeverOverwriteBytesSomeoneStillHolds) {
  const StoreReader store = StoreReader::Open(dir_.string());
  BlockCache cache(&store, 30000);  // room for one or two blocks: constant eviction
  std::vector<std::shared_ptr<const Bytes>> shared;
  std::mt19937_64 rng(7);
  for (int i = 0; i < 2000; ++i) {
    const std::uint64_t key = 1 + rng() % blocks_.size();
    PinnedBlock block = cache.Get({0, key});
    ASSERT_TRUE(std::equal(block.data(), block.data() + block.size(), blocks_[key - 1].begin(), blocks_[key - 1].end()));
    if (i % 50 == 0) shared.push_back(block.Share());  // outlives its cache entry
  }
  EXPECT_GT(cache.Stats().evictions, 1000u);
  for (const auto& bytes : shared) {
    bool matches_some_block = false;
    for (const Bytes& b : blocks_) matches_some_block |= (*bytes == b);
    EXPECT_TRUE(matches_some_block) << "bytes shared out of the cache were recycled under their holder";
  }
}

}  // namespace
}  // namespace octocosm
