#include "storage/block_cache.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <optional>
#include <random>
#include <thread>
#include <vector>

#include "base/error.h"
#include "storage/read_cancellation.h"
#include "tests/storage/cache_test_source.h"

namespace octocosm {
namespace {

using cachetest::Block;
using cachetest::CacheTestSource;
using cachetest::OpenGateOnExit;

constexpr std::size_t Charge(std::size_t size) { return BlockCache::ChargeFor(size); }

// The budget rule every operation must leave true.
void ExpectWithinBudget(const CacheStats& stats) {
  EXPECT_LE(stats.resident_bytes, std::max(stats.capacity_bytes, stats.pinned_bytes))
      << stats.ToString();
  EXPECT_LE(stats.pinned_bytes, stats.resident_bytes) << stats.ToString();
  EXPECT_LE(stats.pinned_entries, stats.entries) << stats.ToString();
}

TEST(BlockCacheTest, GetReadsThroughOnceAndReturnsTheSourceBytes) {
  CacheTestSource source(1000);
  BlockCache cache(&source, 1 << 20);

  PinnedBlock first = cache.Get(Block(7));
  ASSERT_TRUE(first);
  EXPECT_EQ(first.id(), Block(7));
  EXPECT_EQ(first.bytes(), CacheTestSource::ContentOf(Block(7), 1000));
  first.Release();
  EXPECT_FALSE(first);

  PinnedBlock second = cache.Get(Block(7));
  EXPECT_EQ(second.bytes(), CacheTestSource::ContentOf(Block(7), 1000));
  EXPECT_EQ(source.ReadsOf(Block(7)), 1u);

  const CacheStats stats = cache.Stats();
  EXPECT_EQ(stats.misses, 1u);
  EXPECT_EQ(stats.hits, 1u);
  EXPECT_EQ(stats.source_reads, 1u);
  EXPECT_EQ(stats.bytes_read, 1000u);
  EXPECT_EQ(stats.entries, 1u);
  EXPECT_EQ(stats.resident_bytes, Charge(1000));
  EXPECT_EQ(stats.pinned_bytes, Charge(1000));
}

TEST(BlockCacheTest, EvictsLeastRecentlyUsedUntilTheBytesFit) {
  CacheTestSource source;
  source.SetSize(Block(1), 100);
  source.SetSize(Block(2), 200);
  source.SetSize(Block(3), 300);
  source.SetSize(Block(4), 250);
  BlockCache cache(&source, Charge(100) + Charge(200) + Charge(300));

  cache.Get(Block(1));
  cache.Get(Block(2));
  cache.Get(Block(3));
  EXPECT_EQ(cache.Stats().evictions, 0u);
  cache.Get(Block(1));  // recency now, oldest first: 2, 3, 1

  // 250 bytes do not fit in the 200 freed by dropping block 2, so block 3
  // must go too; block 1, used most recently, stays.
  cache.Get(Block(4));
  EXPECT_FALSE(cache.Contains(Block(2)));
  EXPECT_FALSE(cache.Contains(Block(3)));
  EXPECT_TRUE(cache.Contains(Block(1)));
  EXPECT_TRUE(cache.Contains(Block(4)));
  const CacheStats stats = cache.Stats();
  EXPECT_EQ(stats.evictions, 2u);
  EXPECT_EQ(stats.entries, 2u);
  EXPECT_EQ(stats.resident_bytes, Charge(100) + Charge(250));
  ExpectWithinBudget(stats);
}

TEST(BlockCacheTest, TouchAndTryGetRefreshRecencyButContainsDoesNot) {
  CacheTestSource source(100);
  BlockCache cache(&source, 3 * Charge(100));
  cache.Get(Block(1));
  cache.Get(Block(2));
  cache.Get(Block(3));

  EXPECT_TRUE(cache.Touch(Block(1)));     // order: 2, 3, 1
  EXPECT_TRUE(cache.TryGet(Block(2)));    // order: 3, 1, 2
  EXPECT_TRUE(cache.Contains(Block(3)));  // no change
  EXPECT_FALSE(cache.Touch(Block(9)));

  cache.Get(Block(4));
  EXPECT_FALSE(cache.Contains(Block(3)));
  cache.Get(Block(5));
  EXPECT_FALSE(cache.Contains(Block(1)));
  EXPECT_TRUE(cache.Contains(Block(2)));
}

TEST(BlockCacheTest, PinnedBlocksSurviveEvictionPressure) {
  CacheTestSource source(500);
  BlockCache cache(&source, 4 * Charge(500));
  PinnedBlock pinned = cache.Get(Block(0));
  const std::uint8_t* data = pinned.data();

  for (std::uint64_t key = 1; key <= 100; ++key) {
    cache.Get(Block(key));
    ExpectWithinBudget(cache.Stats());
  }
  EXPECT_TRUE(cache.Contains(Block(0)));
  PinnedBlock again = cache.TryGet(Block(0));
  ASSERT_TRUE(again);
  EXPECT_EQ(again.data(), data);  // the same bytes, never re-read
  EXPECT_EQ(source.ReadsOf(Block(0)), 1u);
  EXPECT_EQ(again.bytes(), CacheTestSource::ContentOf(Block(0), 500));
}

TEST(BlockCacheTest, OverBudgetOnlyByPinnedBytesAndBackAfterRelease) {
  CacheTestSource source(1000);
  BlockCache cache(&source, Charge(1000) + Charge(1000) / 2);

  std::vector<PinnedBlock> pins;
  for (std::uint64_t key = 0; key < 4; ++key) pins.push_back(cache.Get(Block(key)));
  CacheStats stats = cache.Stats();
  EXPECT_EQ(stats.resident_bytes, 4 * Charge(1000));
  EXPECT_EQ(stats.pinned_bytes, 4 * Charge(1000));
  EXPECT_EQ(stats.pinned_entries, 4u);
  ExpectWithinBudget(stats);

  pins.erase(pins.begin());  // releases block 0: evicted at once, nothing else may go
  stats = cache.Stats();
  EXPECT_FALSE(cache.Contains(Block(0)));
  EXPECT_EQ(stats.resident_bytes, 3 * Charge(1000));
  ExpectWithinBudget(stats);

  pins.clear();
  stats = cache.Stats();
  EXPECT_LE(stats.resident_bytes, stats.capacity_bytes);
  EXPECT_EQ(stats.entries, 1u);  // only one 1000-byte block fits
  EXPECT_EQ(stats.pinned_bytes, 0u);
  // The survivor is the most recently released block.
  EXPECT_TRUE(cache.Contains(Block(3)));
}

TEST(BlockCacheTest, BlockLargerThanTheBudgetIsServedThenDropped) {
  CacheTestSource source(10'000);
  BlockCache cache(&source, 1000);
  {
    PinnedBlock big = cache.Get(Block(1));
    EXPECT_EQ(big.size(), 10'000u);
    EXPECT_TRUE(cache.Contains(Block(1)));
  }
  EXPECT_FALSE(cache.Contains(Block(1)));
  EXPECT_EQ(cache.Stats().resident_bytes, 0u);
}

TEST(BlockCacheTest, ConcurrentMissesOfOneBlockReadItOnce) {
  CacheTestSource source(4096);
  BlockCache cache(&source, 1 << 20);
  constexpr int kThreads = 8;
  source.CloseGate();

  std::vector<PinnedBlock> results(kThreads);
  std::vector<std::jthread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] { results[t] = cache.Get(Block(42)); });
  }
  OpenGateOnExit open_on_failure(source);
  // One reader reaches the source; the others must be waiting on it, which
  // shows as a miss each, before the read is let through.
  ASSERT_TRUE(source.WaitForReadsStarted(1));
  for (int spins = 0; cache.Stats().misses < kThreads && spins < 20'000; ++spins) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_EQ(cache.Stats().reads_in_flight, 1u);
  source.OpenGate();
  threads.clear();

  EXPECT_EQ(source.ReadsOf(Block(42)), 1u);
  for (const PinnedBlock& result : results) {
    ASSERT_TRUE(result);
    EXPECT_EQ(result.data(), results[0].data());  // one shared copy
  }
  EXPECT_EQ(results[0].bytes(), CacheTestSource::ContentOf(Block(42), 4096));
  CacheStats stats = cache.Stats();
  EXPECT_EQ(stats.misses, static_cast<std::uint64_t>(kThreads));
  EXPECT_EQ(stats.source_reads, 1u);
  EXPECT_EQ(stats.pinned_entries, 1u);
  EXPECT_EQ(stats.reads_in_flight, 0u);

  // The pin count covers every waiter: the block stays pinned until the last
  // handle goes.
  for (int t = 0; t + 1 < kThreads; ++t) results[t].Release();
  EXPECT_EQ(cache.Stats().pinned_entries, 1u);
  results.back().Release();
  stats = cache.Stats();
  EXPECT_EQ(stats.pinned_entries, 0u);
  EXPECT_EQ(stats.pinned_bytes, 0u);
}

TEST(BlockCacheTest, SourceErrorReachesEveryWaiterAndIsNotCached) {
  CacheTestSource source(64);
  BlockCache cache(&source, 1 << 20);
  source.FailWith(Block(5), Error::Corruption("epoch-0.pages", "block 5: checksum mismatch"));
  source.CloseGate();
  constexpr int kThreads = 6;

  std::vector<std::optional<Error>> caught(kThreads);
  std::vector<std::jthread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      try {
        cache.Get(Block(5));
      } catch (const Error& e) {
        caught[t] = e;
      }
    });
  }
  OpenGateOnExit open_on_failure(source);
  ASSERT_TRUE(source.WaitForReadsStarted(1));
  for (int spins = 0; cache.Stats().misses < kThreads && spins < 20'000; ++spins) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  source.OpenGate();
  threads.clear();

  EXPECT_EQ(source.ReadsOf(Block(5)), 1u);
  for (const auto& error : caught) {
    ASSERT_TRUE(error.has_value());
    EXPECT_EQ(error->kind(), ErrorKind::kCorruption);
    EXPECT_STREQ(error->what(), caught[0]->what());
    EXPECT_NE(std::string(error->what()).find("checksum mismatch"), std::string::npos);
  }
  EXPECT_FALSE(cache.Contains(Block(5)));
  CacheStats stats = cache.Stats();
  EXPECT_EQ(stats.read_failures, 1u);
  EXPECT_EQ(stats.entries, 0u);
  EXPECT_EQ(stats.bytes_read, 0u);

  // Nothing was remembered: once the source heals, the next Get reads again.
  source.ClearFailure(Block(5));
  EXPECT_EQ(cache.Get(Block(5)).bytes(), CacheTestSource::ContentOf(Block(5), 64));
  EXPECT_EQ(source.ReadsOf(Block(5)), 2u);
}

// A read its reader cancels (a prefetch no longer wanted,
// storage/read_cancellation.h) throws to that reader only: a Get() waiting
// on it did not cancel, and reads the block itself.
TEST(BlockCacheTest, AWaiterOnACancelledReadReadsTheBlockItself) {
  CacheTestSource source(64);
  BlockCache cache(&source, 1 << 20);
  source.SilentOnce(Block(5));
  std::atomic<bool> cancelled{false};
  std::optional<Error> reader_error;
  std::optional<Bytes> waited;
  std::jthread reader([&] {
    const ReadCancellationScope scope(&cancelled);
    try {
      cache.Get(Block(5));
    } catch (const Error& e) {
      reader_error = e;
    }
  });
  ASSERT_TRUE(source.WaitForReadsStarted(1));
  std::jthread waiter([&] { waited = cache.Get(Block(5)).bytes(); });
  for (int spins = 0; cache.Stats().misses < 2 && spins < 20'000; ++spins) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_EQ(cache.Stats().misses, 2u);
  cancelled = true;
  reader.join();
  waiter.join();
  ASSERT_TRUE(reader_error.has_value());
  EXPECT_NE(std::string(reader_error->what()).find("read cancelled"), std::string::npos) << reader_error->what();
  ASSERT_TRUE(waited.has_value());
  EXPECT_EQ(*waited, CacheTestSource::ContentOf(Block(5), 64));
  EXPECT_EQ(source.ReadsOf(Block(5)), 2u);
  EXPECT_TRUE(cache.Contains(Block(5)));
  EXPECT_EQ(cache.Stats().read_failures, 0u);
}

TEST(BlockCacheTest, NotFoundFromTheSourcePropagatesWithItsKind) {
  CacheTestSource source;
  source.FailWith(Block(3), Error::NotFound("block 3 in epoch 0"));
  BlockCache cache(&source, 1 << 20);
  try {
    cache.Get(Block(3));
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kNotFound);
  }
}

TEST(BlockCacheTest, GetWithoutASourceIsAnInvalidArgumentOnMiss) {
  BlockCache cache(nullptr, 1 << 20);
  try {
    cache.Get(Block(1));
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
  }
  cache.Insert(Block(1), Bytes{1, 2, 3});
  EXPECT_EQ(cache.Get(Block(1)).bytes(), (Bytes{1, 2, 3}));
}

TEST(BlockCacheTest, TryGetNeverReads) {
  CacheTestSource source;
  BlockCache cache(&source, 1 << 20);
  EXPECT_FALSE(cache.TryGet(Block(1)));
  EXPECT_EQ(source.TotalReads(), 0u);
  cache.Get(Block(1));
  EXPECT_TRUE(cache.TryGet(Block(1)));
  const CacheStats stats = cache.Stats();
  EXPECT_EQ(stats.hits, 1u);
  EXPECT_EQ(stats.misses, 2u);
}

TEST(BlockCacheTest, InsertReplacesAndEraseKeepsPinnedBytesValid) {
  BlockCache cache(nullptr, 1 << 20);
  PinnedBlock old_handle = cache.Insert(Block(1), Bytes(100, 0xAA));
  PinnedBlock new_handle = cache.Insert(Block(1), Bytes(50, 0xBB));
  EXPECT_EQ(old_handle.bytes(), Bytes(100, 0xAA));  // still valid for its holder
  EXPECT_EQ(cache.TryGet(Block(1)).bytes(), Bytes(50, 0xBB));
  CacheStats stats = cache.Stats();
  EXPECT_EQ(stats.entries, 1u);
  EXPECT_EQ(stats.resident_bytes, Charge(50));

  EXPECT_TRUE(cache.Erase(Block(1)));
  EXPECT_FALSE(cache.Erase(Block(1)));
  EXPECT_FALSE(cache.Contains(Block(1)));
  EXPECT_EQ(new_handle.bytes(), Bytes(50, 0xBB));
  stats = cache.Stats();
  EXPECT_EQ(stats.entries, 0u);
  EXPECT_EQ(stats.resident_bytes, 0u);
  EXPECT_EQ(stats.pinned_bytes, 0u);
  // Releasing handles to entries no longer in the cache must not disturb it.
  old_handle.Release();
  new_handle.Release();
  EXPECT_EQ(cache.Stats().resident_bytes, 0u);
}

TEST(BlockCacheTest, ClearDropsEverythingButPinnedBytesStayReadable) {
  CacheTestSource source(128);
  BlockCache cache(&source, 1 << 20);
  for (std::uint64_t key = 0; key < 10; ++key) cache.Get(Block(key));
  PinnedBlock kept = cache.Get(Block(3));
  std::shared_ptr<const Bytes> shared = kept.Share();
  cache.Clear();
  const CacheStats stats = cache.Stats();
  EXPECT_EQ(stats.entries, 0u);
  EXPECT_EQ(stats.resident_bytes, 0u);
  EXPECT_EQ(kept.bytes(), CacheTestSource::ContentOf(Block(3), 128));
  kept.Release();
  EXPECT_EQ(*shared, CacheTestSource::ContentOf(Block(3), 128));
  // A cleared block is read again on demand.
  cache.Get(Block(3));
  EXPECT_EQ(source.ReadsOf(Block(3)), 2u);
}

TEST(BlockCacheTest, MovingHandlesTransfersThePin) {
  BlockCache cache(nullptr, 1 << 20);
  PinnedBlock a = cache.Insert(Block(1), Bytes(10, 1));
  PinnedBlock b = std::move(a);
  EXPECT_FALSE(a);  // NOLINT(bugprone-use-after-move): moved-from is documented empty
  EXPECT_TRUE(b);
  EXPECT_EQ(cache.Stats().pinned_entries, 1u);

  PinnedBlock c = cache.Insert(Block(2), Bytes(10, 2));
  c = std::move(b);  // releases block 2, takes over block 1
  CacheStats stats = cache.Stats();
  EXPECT_EQ(stats.pinned_entries, 1u);
  EXPECT_EQ(c.id(), Block(1));
  c = PinnedBlock();
  EXPECT_EQ(cache.Stats().pinned_entries, 0u);
}

TEST(BlockCacheTest, EpochIsPartOfTheIdentity) {
  CacheTestSource source(32);
  BlockCache cache(&source, 1 << 20);
  PinnedBlock a = cache.Get(Block(9, 0));
  PinnedBlock b = cache.Get(Block(9, 1));
  EXPECT_NE(a.bytes(), b.bytes());
  EXPECT_EQ(cache.Stats().entries, 2u);
}

// Many threads hammer a small cache with reads of varied sizes, holding a few
// handles at a time, plus Insert/Erase/TryGet; after every operation the
// budget rule must hold and every handle must carry the right bytes. Run
// under the sanitizer build this also exercises the locking.
TEST(BlockCacheTest, StaysWithinBudgetUnderRandomConcurrentAccess) {
  constexpr std::uint64_t kBlocks = 64;
  constexpr int kThreads = 8;
  constexpr int kOpsPerThread = 1500;
  CacheTestSource source;
  std::mt19937_64 sizes_rng(1234);
  for (std::uint64_t key = 0; key < kBlocks; ++key) {
    source.SetSize(Block(key), 1 + sizes_rng() % 8000);
  }
  BlockCache cache(&source, 40'000);
  std::atomic<int> bad_bytes{0};
  std::atomic<int> budget_violations{0};
  std::atomic<std::uint64_t> lookups{0};

  auto check_budget = [&] {
    const CacheStats stats = cache.Stats();
    if (stats.resident_bytes > std::max(stats.capacity_bytes, stats.pinned_bytes)) {
      ++budget_violations;
    }
  };

  std::vector<std::jthread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937_64 rng(static_cast<std::uint64_t>(t) * 7919 + 1);
      std::vector<PinnedBlock> held;
      for (int op = 0; op < kOpsPerThread; ++op) {
        const BlockId id = Block(rng() % kBlocks);
        const unsigned action = static_cast<unsigned>(rng() % 100);
        if (action < 70) {
          PinnedBlock block = cache.Get(id);
          ++lookups;
          if (block.bytes() != source.ContentOf(id)) ++bad_bytes;
          held.push_back(std::move(block));
        } else if (action < 85) {
          PinnedBlock block = cache.TryGet(id);
          ++lookups;
          if (block && block.bytes() != source.ContentOf(id)) ++bad_bytes;
        } else if (action < 92) {
          cache.Insert(id, source.ContentOf(id));
        } else if (action < 97) {
          cache.Erase(id);
        } else {
          cache.Touch(id);
        }
        if (held.size() > 3) held.erase(held.begin() + static_cast<long>(rng() % held.size()));
        check_budget();
      }
    });
  }
  threads.clear();

  EXPECT_EQ(bad_bytes.load(), 0);
  EXPECT_EQ(budget_violations.load(), 0);
  const CacheStats stats = cache.Stats();
  EXPECT_LE(stats.resident_bytes, stats.capacity_bytes) << stats.ToString();
  EXPECT_EQ(stats.pinned_bytes, 0u);
  EXPECT_EQ(stats.pinned_entries, 0u);
  EXPECT_EQ(stats.reads_in_flight, 0u);
  EXPECT_EQ(stats.lookups(), lookups.load());
  EXPECT_EQ(stats.source_reads, source.TotalReads());
  EXPECT_GT(stats.evictions, 0u);
  // Every byte read is accounted for: the sum over reads of the block sizes.
  std::uint64_t expected_bytes = 0;
  for (const BlockId& id : source.ReadOrder()) expected_bytes += source.SizeOf(id);
  EXPECT_EQ(stats.bytes_read, expected_bytes);
}

TEST(BlockCacheTest, StatsToStringNamesTheNumbers) {
  CacheTestSource source(10);
  BlockCache cache(&source, 1000);
  cache.Get(Block(1));
  const std::string text = cache.Stats().ToString();
  EXPECT_NE(text.find("misses 1"), std::string::npos) << text;
  EXPECT_NE(text.find("/1000 B"), std::string::npos) << text;
}

TEST(BlockCacheTest, LoadReadsTheMissingBlocksWithOneSourceCall) {
  CacheTestSource source;
  source.EnableCoalescing();
  BlockCache cache(&source, 1 << 20);
  cache.Insert(Block(2), CacheTestSource::ContentOf(Block(2), 256));
  const std::vector<BlockId> ids = {Block(1), Block(2), Block(3)};
  EXPECT_EQ(cache.Load(ids), (std::vector<bool>{true, false, true}));
  const auto batches = source.Batches();
  ASSERT_EQ(batches.size(), 1u);
  EXPECT_EQ(batches[0], (std::vector<BlockId>{Block(1), Block(3)}));
  for (std::uint64_t key : {1, 3}) {
    PinnedBlock block = cache.TryGet(Block(key));
    ASSERT_TRUE(block) << key;
    EXPECT_EQ(block.bytes(), source.ContentOf(Block(key)));
  }
  const CacheStats stats = cache.Stats();
  EXPECT_EQ(stats.source_reads, 2u);
  EXPECT_EQ(stats.pinned_entries, 0u);  // cached, not held
  EXPECT_EQ(stats.reads_in_flight, 0u);
  EXPECT_EQ(cache.Load(ids), (std::vector<bool>{false, false, false}));
}

TEST(BlockCacheTest, AFailedLoadCachesNothingAndItsWaitersReadTheirOwnBlocks) {
  CacheTestSource source;
  source.EnableCoalescing();
  source.FailWith(Block(3), Error::Corruption("test server", "block 3 is damaged"));
  BlockCache cache(&source, 1 << 20);
  source.CloseGate();
  OpenGateOnExit open_gate(source);
  std::thread loader([&] {
    const std::vector<BlockId> ids = {Block(1), Block(3)};
    EXPECT_THROW(cache.Load(ids), Error);
  });
  ASSERT_TRUE(source.WaitForReadsStarted(1));
  // A Get() of block 1 waits for the Load's read of it ...
  std::thread getter([&] {
    PinnedBlock block = cache.Get(Block(1));
    EXPECT_EQ(block.bytes(), source.ContentOf(Block(1)));
  });
  for (int i = 0; i < 20000 && cache.Stats().misses < 1; ++i) std::this_thread::sleep_for(std::chrono::microseconds(100));
  source.OpenGate();
  loader.join();
  getter.join();
  // ... which fails for block 3; the Get() reads block 1 itself, and gets it.
  EXPECT_EQ(source.ReadsOf(Block(1)), 2u);
  EXPECT_TRUE(cache.Contains(Block(1)));
  EXPECT_FALSE(cache.Contains(Block(3)));
  EXPECT_EQ(cache.Stats().read_failures, 2u);
}

}  // namespace
}  // namespace octocosm
