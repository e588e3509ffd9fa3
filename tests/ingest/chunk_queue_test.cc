// ChunkQueue (ingest/chunk_queue.h): every chunk once, the largest of
// the window first, never more than the window past the first not taken,
// and so no chunk passed over for good.
#include "ingest/chunk_queue.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <mutex>
#include <random>
#include <thread>
#include <vector>

namespace octocosm {
namespace {

// Takes every chunk on one thread, checking the window on the way.
std::vector<std::size_t> TakeAll(const std::vector<std::uint64_t>& counts, std::size_t window) {
  ChunkQueue queue(counts, window);
  std::vector<std::size_t> order;
  std::vector<bool> taken(counts.size());
  std::size_t first_open = 0;
  for (std::size_t c = queue.Take(); c < counts.size(); c = queue.Take()) {
    EXPECT_FALSE(taken[c]) << "chunk " << c << " taken twice";
    EXPECT_LT(c, first_open + std::max<std::size_t>(window, 1)) << "chunk " << c << " beyond the window";
    for (std::size_t d = first_open; d < std::min(counts.size(), first_open + std::max<std::size_t>(window, 1)); ++d) {
      EXPECT_TRUE(taken[d] || counts[d] <= counts[c]) << "chunk " << c << " taken before the larger " << d;
    }
    taken[c] = true;
    order.push_back(c);
    while (first_open < counts.size() && taken[first_open]) ++first_open;
  }
  EXPECT_EQ(order.size(), counts.size());
  EXPECT_EQ(queue.Take(), counts.size()) << "nothing left after the last";
  return order;
}

TEST(ChunkQueue, AWindowOfOneIsDepthFirstOrder) {
  const std::vector<std::size_t> order = TakeAll({5, 9, 1, 7}, 1);
  EXPECT_EQ(order, (std::vector<std::size_t>{0, 1, 2, 3}));
  EXPECT_EQ(TakeAll({5, 9, 1, 7}, 0), order);
}

TEST(ChunkQueue, TakesTheLargestOfTheWindowSoTheSmallComeLast) {
  EXPECT_EQ(TakeAll({5, 9, 1, 7, 3}, 3), (std::vector<std::size_t>{1, 0, 3, 4, 2}));
  EXPECT_EQ(TakeAll({2, 2, 2}, 3), (std::vector<std::size_t>{0, 1, 2})) << "ties in depth-first order";
}

TEST(ChunkQueue, ASmallChunkIsTakenOnceTheWindowHasPassedIt) {
  // Sizes growing along the order: a window counted in chunks not yet taken
  // would always see a larger one and leave chunk 0 for the very end.
  std::vector<std::uint64_t> growing(100);
  for (std::size_t c = 0; c < growing.size(); ++c) growing[c] = c + 1;
  const std::vector<std::size_t> order = TakeAll(growing, 8);
  EXPECT_LT(std::find(order.begin(), order.end(), 0) - order.begin(), 8);
}

TEST(ChunkQueue, RandomSizesFromSeveralThreadsTakeEachChunkOnce) {
  std::mt19937_64 random(3);
  std::vector<std::uint64_t> counts(5000);
  for (std::uint64_t& c : counts) c = random() % 300000;
  ChunkQueue queue(counts, 8);
  std::mutex mutex;
  std::vector<int> times(counts.size());
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (std::size_t c = queue.Take(); c < counts.size(); c = queue.Take()) {
        std::lock_guard lock(mutex);
        ++times[c];
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_TRUE(std::all_of(times.begin(), times.end(), [](int n) { return n == 1; }));
  TakeAll(counts, 8);
}

}  // namespace
}  // namespace octocosm
