#include "storage/prefetcher.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <random>
#include <thread>
#include <vector>

#include "base/error.h"
#include "tests/storage/cache_test_source.h"

namespace octocosm {
namespace {

using cachetest::Block;
using cachetest::CacheTestSource;
using cachetest::OpenGateOnExit;

std::vector<BlockId> Blocks(std::initializer_list<std::uint64_t> keys) {
  std::vector<BlockId> ids;
  for (std::uint64_t key : keys) ids.push_back(Block(key));
  return ids;
}

Prefetcher::Options Workers(std::size_t count) {
  Prefetcher::Options options;
  options.workers = count;
  return options;
}

// Every queued request ends in exactly one outcome or is still queued or in flight.
void ExpectAccountingBalances(const PrefetchStats& stats) {
  EXPECT_EQ(stats.queued, stats.completed + stats.found_resident + stats.failed +
                              stats.cancelled + stats.queue_depth + stats.in_flight)
      << stats.ToString();
}

TEST(PrefetcherTest, OneWorkerReadsASubmittedListInPriorityOrder) {
  CacheTestSource source(64);
  BlockCache cache(&source, 1 << 20);
  Prefetcher prefetcher(cache, Workers(1));
  const std::vector<BlockId> wanted = Blocks({17, 3, 99, 4, 250, 1, 8});

  EXPECT_EQ(prefetcher.Submit(wanted), wanted.size());
  prefetcher.Drain();

  EXPECT_EQ(source.ReadOrder(), wanted);
  for (const BlockId& id : wanted) {
    PinnedBlock block = cache.TryGet(id);
    ASSERT_TRUE(block);
    EXPECT_EQ(block.bytes(), CacheTestSource::ContentOf(id, 64));
  }
  const PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.queued, wanted.size());
  EXPECT_EQ(stats.completed, wanted.size());
  EXPECT_EQ(stats.queue_depth, 0u);
  EXPECT_EQ(stats.in_flight, 0u);
  ExpectAccountingBalances(stats);
  // Prefetched blocks are left unpinned.
  EXPECT_EQ(cache.Stats().pinned_entries, 0u);
}

TEST(PrefetcherTest, DuplicatesInAListKeepTheirFirstPosition) {
  CacheTestSource source;
  BlockCache cache(&source, 1 << 20);
  Prefetcher prefetcher(cache, Workers(1));
  const std::vector<BlockId> wanted = Blocks({5, 6, 5, 7, 6});
  EXPECT_EQ(prefetcher.Submit(wanted), 3u);
  prefetcher.Drain();
  EXPECT_EQ(source.ReadOrder(), Blocks({5, 6, 7}));

  // Resident duplicates are one hit each block, not each mention.
  EXPECT_EQ(prefetcher.Submit(Blocks({5, 8, 5, 6, 6})), 1u);
  prefetcher.Drain();
  EXPECT_EQ(prefetcher.Stats().hits, 2u);

  // Duplicates of blocks already pending keep their first position too.
  {
    OpenGateOnExit open_on_failure(source);
    source.CloseGate();
    prefetcher.Submit(Blocks({1, 2}));
    ASSERT_TRUE(source.WaitForReadsStarted(5));  // 5, 6, 7, 8, then 1 at the gate
    EXPECT_EQ(prefetcher.Submit(Blocks({3, 2, 4, 2, 3, 1})), 3u);
  }
  prefetcher.Drain();
  EXPECT_EQ(source.ReadOrder(), Blocks({5, 6, 7, 8, 1, 3, 2, 4}));
  const PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.cancelled, 0u);
  ExpectAccountingBalances(stats);
}

TEST(PrefetcherTest, ResubmittingReranksAndCancelsWhatIsNoLongerWanted) {
  CacheTestSource source;
  BlockCache cache(&source, 1 << 20);
  Prefetcher prefetcher(cache, Workers(1));
  OpenGateOnExit open_on_failure(source);
  source.CloseGate();

  prefetcher.Submit(Blocks({1, 2, 3, 4, 5}));
  ASSERT_TRUE(source.WaitForReadsStarted(1));  // the worker holds block 1 at the gate

  // Next frame: 5 is now most important, 2 and 4 are out of view, 6 is new,
  // and 1 is already being read.
  EXPECT_EQ(prefetcher.Submit(Blocks({5, 3, 1, 6})), 3u);
  PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.queue_depth, 3u);
  EXPECT_EQ(stats.in_flight, 1u);
  EXPECT_EQ(stats.cancelled, 2u);
  EXPECT_EQ(stats.queued, 6u);  // 1-5, then only 6 is new
  ExpectAccountingBalances(stats);

  source.OpenGate();
  prefetcher.Drain();
  EXPECT_EQ(source.ReadOrder(), Blocks({1, 5, 3, 6}));
  EXPECT_EQ(source.ReadsOf(Block(2)), 0u);
  EXPECT_EQ(source.ReadsOf(Block(4)), 0u);
  EXPECT_FALSE(cache.Contains(Block(2)));
  stats = prefetcher.Stats();
  EXPECT_EQ(stats.completed, 4u);
  ExpectAccountingBalances(stats);

  // Everything wanted is now resident: a repeat request reads nothing.
  EXPECT_EQ(prefetcher.Submit(Blocks({5, 3, 1, 6})), 0u);
  prefetcher.Drain();
  EXPECT_EQ(source.TotalReads(), 4u);
  EXPECT_EQ(prefetcher.Stats().hits, 4u);
}

TEST(PrefetcherTest, ResidentBlocksAreSkippedAsHitsAndRefreshed) {
  CacheTestSource source(100);
  BlockCache cache(&source, 3 * BlockCache::ChargeFor(100));
  cache.Get(Block(1));
  cache.Get(Block(2));
  cache.Get(Block(3));  // LRU order, oldest first: 1, 2, 3
  Prefetcher prefetcher(cache, Workers(1));

  // Block 1 is wanted and resident: it is refreshed, so block 2 is the one
  // the new block 4 pushes out.
  EXPECT_EQ(prefetcher.Submit(Blocks({1, 4})), 1u);
  prefetcher.Drain();
  EXPECT_EQ(source.ReadsOf(Block(1)), 1u);
  EXPECT_TRUE(cache.Contains(Block(1)));
  EXPECT_FALSE(cache.Contains(Block(2)));
  EXPECT_TRUE(cache.Contains(Block(4)));
  const PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.hits, 1u);
  EXPECT_EQ(stats.queued, 1u);
  EXPECT_EQ(stats.completed, 1u);
}

TEST(PrefetcherTest, AddTakesThePendingRequestWithTheLowestPriorityFirst) {
  CacheTestSource source;
  BlockCache cache(&source, 1 << 20);
  Prefetcher prefetcher(cache, Workers(1));
  OpenGateOnExit open_on_failure(source);
  source.CloseGate();
  ASSERT_TRUE(prefetcher.Add(Block(100), 0));
  ASSERT_TRUE(source.WaitForReadsStarted(1));

  EXPECT_TRUE(prefetcher.Add(Block(1), 50));
  EXPECT_TRUE(prefetcher.Add(Block(2), 10));
  EXPECT_TRUE(prefetcher.Add(Block(3), 30));
  EXPECT_TRUE(prefetcher.Add(Block(4), 30));  // ties go in queue order
  EXPECT_TRUE(prefetcher.Add(Block(1), 5));   // re-rank, not a second request
  EXPECT_FALSE(prefetcher.Add(Block(100), 0));  // in flight
  EXPECT_EQ(prefetcher.Stats().queue_depth, 4u);

  source.OpenGate();
  prefetcher.Drain();
  EXPECT_EQ(source.ReadOrder(), Blocks({100, 1, 2, 3, 4}));
  EXPECT_FALSE(prefetcher.Add(Block(2), 0));  // resident
  const PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.queued, 5u);
  EXPECT_EQ(stats.hits, 1u);
  ExpectAccountingBalances(stats);
}

TEST(PrefetcherTest, CancelledRequestsAreNeverRead) {
  CacheTestSource source;
  BlockCache cache(&source, 1 << 20);
  Prefetcher prefetcher(cache, Workers(1));
  OpenGateOnExit open_on_failure(source);
  source.CloseGate();
  prefetcher.Submit(Blocks({1, 2, 3, 4, 5, 6}));
  ASSERT_TRUE(source.WaitForReadsStarted(1));

  EXPECT_TRUE(prefetcher.Cancel(Block(3)));
  EXPECT_FALSE(prefetcher.Cancel(Block(3)));   // no longer pending
  EXPECT_FALSE(prefetcher.Cancel(Block(1)));   // in flight, not pending (a read from a server would stop)
  EXPECT_FALSE(prefetcher.Cancel(Block(77)));  // never asked for
  prefetcher.WaitFor(Block(3));                // returns at once: not pending
  EXPECT_EQ(prefetcher.Stats().queue_depth, 4u);
  EXPECT_EQ(prefetcher.CancelAll(), 4u);
  EXPECT_EQ(prefetcher.CancelAll(), 0u);

  source.OpenGate();
  prefetcher.Drain();
  EXPECT_EQ(source.ReadOrder(), Blocks({1}));
  const PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.cancelled, 5u);
  EXPECT_EQ(stats.completed, 1u);
  ExpectAccountingBalances(stats);
}

// A block read from a server that the next Submit no longer wants stops
// while the server keeps it waiting: counted as cancelled, not as a failure,
// no error remembered, no callback. Wanted again, it is read anew.
TEST(PrefetcherTest, AReadFromAServerNoLongerWantedStops) {
  CacheTestSource source;
  BlockCache cache(&source, 1 << 20);
  std::atomic<int> callbacks{0};
  Prefetcher::Options options = Workers(1);
  options.on_complete = [&](const BlockId&, const Error*) { ++callbacks; };
  Prefetcher prefetcher(cache, options);
  source.SilentOnce(Block(1));
  prefetcher.Submit(Blocks({1, 2}));
  ASSERT_TRUE(source.WaitForReadsStarted(1));
  prefetcher.Submit(Blocks({2}));
  prefetcher.Drain();
  PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.cancelled, 1u) << stats.ToString();
  EXPECT_EQ(stats.completed, 1u) << stats.ToString();
  EXPECT_EQ(stats.failed, 0u) << stats.ToString();
  ExpectAccountingBalances(stats);
  EXPECT_FALSE(prefetcher.LastError(Block(1)).has_value());
  EXPECT_EQ(callbacks.load(), 1);
  EXPECT_FALSE(cache.Contains(Block(1)));
  EXPECT_TRUE(cache.Contains(Block(2)));
  EXPECT_EQ(cache.Stats().read_failures, 0u);

  prefetcher.Submit(Blocks({1}));
  prefetcher.Drain();
  EXPECT_TRUE(cache.Contains(Block(1)));
  EXPECT_EQ(source.ReadsOf(Block(1)), 2u);
  stats = prefetcher.Stats();
  EXPECT_EQ(stats.completed, 2u) << stats.ToString();
  ExpectAccountingBalances(stats);
}

// Cancel() and CancelAll() stop reads in flight from a server too; the
// destructor stops them rather than waiting for the server.
TEST(PrefetcherTest, CancelAndDestructionStopReadsInFlight) {
  CacheTestSource source;
  BlockCache cache(&source, 1 << 20);
  {
    Prefetcher prefetcher(cache, Workers(2));
    source.SilentOnce(Block(1));
    source.SilentOnce(Block(2));
    prefetcher.Submit(Blocks({1, 2}));
    ASSERT_TRUE(source.WaitForReadsStarted(2));
    EXPECT_FALSE(prefetcher.Cancel(Block(1)));  // in flight, not pending
    prefetcher.WaitFor(Block(1));
    EXPECT_EQ(prefetcher.Stats().cancelled, 1u);
    EXPECT_EQ(prefetcher.CancelAll(), 0u);
    prefetcher.Drain();
    EXPECT_EQ(prefetcher.Stats().cancelled, 2u);
  }
  const auto start = std::chrono::steady_clock::now();
  {
    Prefetcher prefetcher(cache, Workers(1));
    source.SilentOnce(Block(3));
    prefetcher.Submit(Blocks({3}));
    ASSERT_TRUE(source.WaitForReadsStarted(3));
  }
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));  // the silent read gives up at 20 s
  EXPECT_EQ(cache.Stats().entries, 0u);
}

TEST(PrefetcherTest, FailuresAreCountedAndRememberedNotThrown) {
  CacheTestSource source;
  source.FailWith(Block(2), Error::Corruption("epoch-0.pages", "block 2: checksum mismatch"));
  source.FailWith(Block(4), Error::Io("epoch-0.pages", "pread failed"));
  BlockCache cache(&source, 1 << 20);
  std::mutex seen_mutex;
  std::vector<std::pair<BlockId, std::optional<ErrorKind>>> seen;
  Prefetcher::Options options;
  options.workers = 2;
  options.on_complete = [&](const BlockId& id, const Error* error) {
    std::lock_guard lock(seen_mutex);
    seen.emplace_back(id, error ? std::optional(error->kind()) : std::nullopt);
  };
  Prefetcher prefetcher(cache, options);

  prefetcher.Submit(Blocks({1, 2, 3, 4}));
  prefetcher.Drain();

  PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.failed, 2u);
  EXPECT_EQ(stats.completed, 2u);
  ExpectAccountingBalances(stats);
  ASSERT_TRUE(prefetcher.LastError(Block(2)).has_value());
  EXPECT_EQ(prefetcher.LastError(Block(2))->kind(), ErrorKind::kCorruption);
  EXPECT_EQ(prefetcher.LastError(Block(4))->kind(), ErrorKind::kIo);
  EXPECT_FALSE(prefetcher.LastError(Block(1)).has_value());
  EXPECT_FALSE(cache.Contains(Block(2)));
  {
    std::lock_guard lock(seen_mutex);
    EXPECT_EQ(seen.size(), 4u);
    for (const auto& [id, kind] : seen) {
      if (id == Block(2)) {
        EXPECT_EQ(kind, ErrorKind::kCorruption);
      } else if (id == Block(4)) {
        EXPECT_EQ(kind, ErrorKind::kIo);
      } else {
        EXPECT_FALSE(kind.has_value());
      }
    }
  }

  // A later successful prefetch clears the remembered error.
  source.ClearFailure(Block(2));
  prefetcher.Submit(Blocks({2}));
  prefetcher.WaitFor(Block(2));
  EXPECT_FALSE(prefetcher.LastError(Block(2)).has_value());
  EXPECT_TRUE(cache.Contains(Block(2)));
  EXPECT_TRUE(prefetcher.LastError(Block(4)).has_value());
}

TEST(PrefetcherTest, NonErrorExceptionsAndThrowingCallbacksDoNotEscapeWorkers) {
  class BadAllocSource : public BlockSource {
   public:
    Bytes ReadBlock(const BlockId&) const override { throw std::bad_alloc(); }
  };
  BadAllocSource source;
  BlockCache cache(&source, 1 << 20);
  Prefetcher::Options options;
  options.workers = 1;
  options.on_complete = [](const BlockId&, const Error*) { throw std::runtime_error("oops"); };
  Prefetcher prefetcher(cache, options);
  prefetcher.Submit(Blocks({1, 2}));
  prefetcher.Drain();
  const PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.failed, 2u);
  EXPECT_EQ(stats.callback_errors, 2u);
  const std::optional<Error> error = prefetcher.LastError(Block(1));
  ASSERT_TRUE(error.has_value());
  EXPECT_NE(std::string(error->what()).find("key 0x1"), std::string::npos) << error->what();
}

TEST(PrefetcherTest, WaitForReturnsOnceTheBlockIsResident) {
  CacheTestSource source;
  source.SetDelay(std::chrono::milliseconds(2));
  BlockCache cache(&source, 1 << 20);
  Prefetcher prefetcher(cache);
  EXPECT_EQ(prefetcher.Stats().workers, 2u);
  prefetcher.Submit(Blocks({1, 2, 3, 4, 5, 6, 7, 8}));
  prefetcher.WaitFor(Block(8));
  EXPECT_TRUE(cache.Contains(Block(8)));
}

TEST(PrefetcherTest, ZeroWorkersIsAnInvalidArgument) {
  BlockCache cache(nullptr, 1000);
  try {
    Prefetcher prefetcher(cache, Workers(0));
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
  }
}

TEST(PrefetcherTest, DestructionWithAFullQueueDropsItAndJoins) {
  CacheTestSource source;
  BlockCache cache(&source, 1 << 20);
  std::vector<BlockId> wanted;
  for (std::uint64_t key = 0; key < 1000; ++key) wanted.push_back(Block(key));
  source.CloseGate();
  source.SetDelay(std::chrono::milliseconds(1));
  {
    std::jthread opener;  // declared first, so joined after ~Prefetcher
    Prefetcher prefetcher(cache, Workers(2));
    OpenGateOnExit open_on_failure(source);
    prefetcher.Submit(wanted);
    ASSERT_TRUE(source.WaitForReadsStarted(2));  // both workers are stuck in a read
    // Let the reads go only once the destructor has had time to start: the
    // reads in flight must finish and no queued one may start.
    open_on_failure.Dismiss();
    opener = std::jthread([&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      source.OpenGate();
    });
  }
  const std::size_t reads = source.TotalReads();
  EXPECT_LT(reads, wanted.size());
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_EQ(source.TotalReads(), reads);  // no worker outlived the Prefetcher
  EXPECT_EQ(cache.Stats().pinned_entries, 0u);
}

// Several threads replace the request list and read in the foreground at
// once, on a cache too small for everything; the accounting must balance and
// the cache must end within budget with nothing pinned.
// Four threads submit, add, cancel and read in the foreground at once; with
// `coalescing`, the workers read neighbouring blocks together.
void ConcurrentSubmitsAndForegroundReads(bool coalescing) {
  constexpr std::uint64_t kBlocks = 200;
  CacheTestSource source(1000);
  if (coalescing) source.EnableCoalescing();
  source.FailWith(Block(13), Error::Corruption("epoch-0.pages", "block 13: checksum mismatch"));
  BlockCache cache(&source, 50 * BlockCache::ChargeFor(1000));
  Prefetcher prefetcher(cache, Workers(4));
  std::atomic<int> bad_bytes{0};

  std::vector<std::jthread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937_64 rng(static_cast<std::uint64_t>(t) + 99);
      for (int frame = 0; frame < 150; ++frame) {
        std::vector<BlockId> wanted;
        const std::uint64_t start = rng() % kBlocks;
        for (std::uint64_t i = 0; i < 30; ++i) wanted.push_back(Block((start + i) % kBlocks));
        prefetcher.Submit(wanted);
        if (frame % 5 == 0) {
          prefetcher.Add(Block(rng() % kBlocks), static_cast<std::int64_t>(rng() % 40));
        }
        if (frame % 7 == 0) prefetcher.Cancel(Block(rng() % kBlocks));
        const BlockId id = Block(rng() % kBlocks);
        try {
          PinnedBlock block = cache.Get(id);
          if (block.bytes() != CacheTestSource::ContentOf(id, 1000)) ++bad_bytes;
        } catch (const Error& e) {
          if (!(id == Block(13)) || e.kind() != ErrorKind::kCorruption) ++bad_bytes;
        }
        PrefetchStats stats = prefetcher.Stats();
        if (stats.queued != stats.completed + stats.found_resident + stats.failed +
                                stats.cancelled + stats.queue_depth + stats.in_flight) {
          ++bad_bytes;
        }
      }
    });
  }
  threads.clear();
  prefetcher.Drain();

  EXPECT_EQ(bad_bytes.load(), 0);
  const PrefetchStats stats = prefetcher.Stats();
  ExpectAccountingBalances(stats);
  EXPECT_EQ(stats.queue_depth, 0u);
  EXPECT_EQ(stats.in_flight, 0u);
  EXPECT_GT(stats.completed, 0u);
  const CacheStats cache_stats = cache.Stats();
  EXPECT_LE(cache_stats.resident_bytes, cache_stats.capacity_bytes) << cache_stats.ToString();
  EXPECT_EQ(cache_stats.pinned_entries, 0u);
  EXPECT_EQ(cache_stats.source_reads, source.TotalReads());
  if (coalescing) {
    EXPECT_GT(source.Batches().size(), 0u);
  }
}

TEST(PrefetcherTest, ConcurrentSubmitsAndForegroundReadsStayConsistent) { ConcurrentSubmitsAndForegroundReads(false); }

TEST(PrefetcherTest, ConcurrentUseWithReadsOfSeveralBlocksStaysConsistent) { ConcurrentSubmitsAndForegroundReads(true); }

TEST(PrefetcherTest, NeighbouringBlocksFromAServerAreReadTogether) {
  CacheTestSource source;
  source.EnableCoalescing();  // block k at byte k * 1000, 256 bytes each
  BlockCache cache(&source, 1 << 20);
  Prefetcher::Options options;
  options.workers = 1;
  Prefetcher prefetcher(cache, options);
  // Blocks 1-10 lie 744 bytes apart; block 500 half a megabyte away.
  prefetcher.Submit(Blocks({1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 500}));
  prefetcher.Drain();
  const auto batches = source.Batches();
  ASSERT_EQ(batches.size(), 1u);
  EXPECT_EQ(batches[0], Blocks({1, 2, 3, 4, 5, 6, 7, 8, 9, 10}));
  EXPECT_EQ(source.ReadsOf(Block(500)), 1u);
  for (std::uint64_t key : {1, 5, 10, 500}) EXPECT_TRUE(cache.Contains(Block(key))) << key;
  const PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.completed, 11u);
  EXPECT_EQ(stats.in_flight, 0u);
  EXPECT_EQ(stats.queued, stats.completed + stats.found_resident + stats.failed + stats.cancelled);
}

TEST(PrefetcherTest, AFailedReadOfSeveralBlocksReadsEachAlone) {
  CacheTestSource source;
  source.EnableCoalescing();
  source.FailWith(Block(4), Error::Corruption("test server", "block 4 is damaged"));
  BlockCache cache(&source, 1 << 20);
  Prefetcher::Options options;
  options.workers = 1;
  std::atomic<int> errors{0};
  options.on_complete = [&](const BlockId&, const Error* error) {
    if (error != nullptr) ++errors;
  };
  Prefetcher prefetcher(cache, options);
  prefetcher.Submit(Blocks({1, 2, 3, 4, 5, 6}));
  prefetcher.Drain();
  ASSERT_EQ(source.Batches().size(), 1u);
  // Each block was then read alone: only block 4 fails, with its own error.
  EXPECT_EQ(source.ReadsOf(Block(2)), 2u);
  const PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.completed, 5u);
  EXPECT_EQ(stats.failed, 1u);
  EXPECT_EQ(errors.load(), 1);
  ASSERT_TRUE(prefetcher.LastError(Block(4)).has_value());
  EXPECT_NE(std::string(prefetcher.LastError(Block(4))->what()).find("block 4 is damaged"), std::string::npos);
  EXPECT_FALSE(prefetcher.LastError(Block(2)).has_value());
  EXPECT_TRUE(cache.Contains(Block(6)));
}

TEST(PrefetcherTest, AReadOfSeveralBlocksStopsOnlyWhenNoneIsWanted) {
  CacheTestSource source;
  source.EnableCoalescing();
  source.SilentOnce(Block(1));  // the server sends nothing for this read
  BlockCache cache(&source, 1 << 20);
  Prefetcher::Options options;
  options.workers = 1;
  Prefetcher prefetcher(cache, options);
  prefetcher.Submit(Blocks({1, 2, 3}));
  ASSERT_TRUE(source.WaitForReadsStarted(3));
  ASSERT_EQ(source.Batches().size(), 1u);
  // Block 2 is still wanted: the read goes on.
  prefetcher.Submit(Blocks({2}));
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(prefetcher.Stats().in_flight, 3u);
  EXPECT_EQ(prefetcher.Stats().cancelled, 0u);
  // None is: it stops, and all three count as cancelled.
  prefetcher.Submit({});
  prefetcher.Drain();
  PrefetchStats stats = prefetcher.Stats();
  EXPECT_EQ(stats.cancelled, 3u);
  EXPECT_EQ(stats.completed, 0u);
  EXPECT_FALSE(cache.Contains(Block(2)));
  // Asked for again, they are read.
  prefetcher.Submit(Blocks({1, 2, 3}));
  prefetcher.Drain();
  stats = prefetcher.Stats();
  EXPECT_EQ(stats.completed, 3u);
  EXPECT_TRUE(cache.Contains(Block(1)));
}

}  // namespace
}  // namespace octocosm
