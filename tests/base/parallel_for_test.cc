// ParallelFor and ParallelForDynamic (base/parallel_for.h): every item once,
// in the documented ranges, and errors back on the calling thread.
#include "base/parallel_for.h"

#include <gtest/gtest.h>
#include <sched.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <chrono>
#include <cstddef>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

namespace octocosm {
namespace {

// The ranges a loop's body was called with, from any thread.
struct Ranges {
  void Add(std::size_t begin, std::size_t end) {
    std::lock_guard lock(mutex);
    seen.emplace_back(begin, end);
  }
  std::mutex mutex;
  std::vector<std::pair<std::size_t, std::size_t>> seen;
};

TEST(ParallelForDynamic, CoversEveryItemOnceInPiecesOfTheGrain) {
  for (const std::size_t count : {0u, 1u, 99u, 100u, 101u, 1000u, 12345u}) {
    for (const int threads : {1, 2, 3, 8}) {
      for (const std::size_t grain : {1u, 7u, 100u, 5000u}) {
        std::vector<std::atomic<int>> hits(count);
        Ranges ranges;
        ParallelForDynamic(count, threads, grain, [&](std::size_t begin, std::size_t end) {
          ranges.Add(begin, end);
          for (std::size_t i = begin; i < end; ++i) ++hits[i];
        });
        for (std::size_t i = 0; i < count; ++i) ASSERT_EQ(hits[i], 1) << count << " " << threads << " " << grain << " " << i;
        const std::size_t pieces = (count + grain - 1) / grain;
        EXPECT_EQ(ranges.seen.size(), count == 0 ? 0 : (threads == 1 ? 1 : pieces)) << count << " " << threads << " " << grain;
        if (threads == 1) continue;
        for (const auto& [begin, end] : ranges.seen) {
          EXPECT_EQ(begin % grain, 0u);
          EXPECT_EQ(end, std::min(count, begin + grain));
        }
      }
    }
  }
}

TEST(ParallelForDynamic, AThreadHeldUpLeavesTheRestToTheOthers) {
  // The calling thread is held in its first piece until the other thread has
  // done every other piece, which only a dynamic split lets it do: a static
  // one would leave half the items waiting for the caller (the wait's minute
  // is there to fail rather than hang, not to time anything).
  const std::thread::id caller = std::this_thread::get_id();
  std::mutex mutex;
  std::condition_variable others_done;
  std::size_t by_others = 0;
  std::atomic<std::size_t> by_caller{0};
  std::atomic<bool> held{false};
  ParallelForDynamic(1000, 2, 10, [&](std::size_t begin, std::size_t end) {
    if (std::this_thread::get_id() != caller) {
      std::lock_guard lock(mutex);
      by_others += end - begin;
      others_done.notify_all();
      return;
    }
    if (!held.exchange(true)) {
      std::unique_lock lock(mutex);
      others_done.wait_for(lock, std::chrono::minutes(1), [&] { return by_others + (end - begin) == 1000; });
    }
    by_caller += end - begin;
  });
  EXPECT_EQ(by_others + by_caller, 1000u);
  EXPECT_LE(by_caller, 10u) << "the caller did at most the piece it was held in";
}

TEST(ParallelForDynamic, AnErrorIsRethrownOnTheCallingThreadAndStopsTheRest) {
  std::atomic<std::size_t> ran{0};
  std::atomic<bool> thrown{false};
  EXPECT_THROW(ParallelForDynamic(100000, 2, 10, [&](std::size_t begin, std::size_t) {
                 ++ran;
                 if (begin == 500) {
                   thrown = true;
                   throw std::runtime_error("piece 50");
                 }
                 // Pieces after the failing one take a millisecond each, so
                 // the other thread could take them all only if the failing
                 // thread stalled for ten seconds between its throw and the
                 // error's record (a piece already running finishes).
                 if (begin > 500) std::this_thread::sleep_for(std::chrono::milliseconds(1));
               }),
               std::runtime_error);
  EXPECT_TRUE(thrown);
  EXPECT_LT(ran, 10000u);  // the pieces after the error are not taken
}

TEST(ParallelFor, OneContiguousRangePerThread) {
  Ranges ranges;
  ParallelFor(10000, 3, [&](std::size_t begin, std::size_t end) { ranges.Add(begin, end); }, 1);
  std::sort(ranges.seen.begin(), ranges.seen.end());
  ASSERT_EQ(ranges.seen.size(), 3u);
  EXPECT_EQ(ranges.seen[0].first, 0u);
  EXPECT_EQ(ranges.seen[0].second, ranges.seen[1].first);
  EXPECT_EQ(ranges.seen[1].second, ranges.seen[2].first);
  EXPECT_EQ(ranges.seen[2].second, 10000u);
}

TEST(RunWorkers, EachWorkerRunsOnceTheCallerAsWorkerZero) {
  std::mutex mutex;
  std::vector<int> seen;
  std::thread::id zero;
  RunWorkers(4, [&](int worker, const std::atomic<bool>&) {
    std::lock_guard lock(mutex);
    seen.push_back(worker);
    if (worker == 0) zero = std::this_thread::get_id();
  });
  std::sort(seen.begin(), seen.end());
  EXPECT_EQ(seen, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(zero, std::this_thread::get_id());
}

// A worker's error sets `stop` for the others (here worker 0 waits for it,
// with no clock in the test's verdict) and reaches the caller once all have
// returned.
TEST(RunWorkers, AnErrorSetsStopForTheOthersAndIsRethrown) {
  std::atomic<bool> saw_stop{false};
  std::atomic<bool> returned_before_rethrow{false};
  try {
    RunWorkers(2, [&](int worker, const std::atomic<bool>& stop) {
      if (worker == 1) throw std::runtime_error("worker 1 failed");
      // A guard against a hang should `stop` never turn true: a minute.
      for (int i = 0; i < 60000 && !stop; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      saw_stop = stop.load();
      returned_before_rethrow = true;
    });
    ADD_FAILURE() << "the error was not rethrown";
  } catch (const std::runtime_error& error) {
    EXPECT_STREQ(error.what(), "worker 1 failed");
  }
  EXPECT_TRUE(saw_stop);
  EXPECT_TRUE(returned_before_rethrow);
}

// A process that may run on one core (taskset, a cpuset, mpirun's binding of
// a rank) gets one thread by default, not one per core of the machine.
TEST(ResolveThreadCount, DefaultsToTheCoresThisThreadMayRunOn) {
  EXPECT_GE(CoresAllowed(), 1u);
  EXPECT_EQ(ResolveThreadCount(0), static_cast<int>(CoresAllowed()));
  EXPECT_EQ(ResolveThreadCount(5), 5);
  unsigned bound = 0;
  std::thread([&] {  // affinity is per thread: this one's only
    cpu_set_t one;
    CPU_ZERO(&one);
    cpu_set_t all;
    ASSERT_EQ(::sched_getaffinity(0, sizeof all, &all), 0);
    int first = 0;
    while (!CPU_ISSET(first, &all)) ++first;
    CPU_SET(first, &one);
    ASSERT_EQ(::sched_setaffinity(0, sizeof one, &one), 0);
    bound = CoresAllowed();
    EXPECT_EQ(ResolveThreadCount(0), 1);
  }).join();
  EXPECT_EQ(bound, 1u);
}

}  // namespace
}  // namespace octocosm
