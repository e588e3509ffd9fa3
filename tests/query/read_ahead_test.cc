// ReadAhead hands results out in input order, keeps at most its depth of
// reads running, and passes a read's error to the caller at that read.
#include "query/read_ahead.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace octocosm {
namespace {

std::vector<int> Range(int n) {
  std::vector<int> values(n);
  for (int i = 0; i < n; ++i) values[i] = i;
  return values;
}

TEST(ReadAhead, HandsResultsOutInInputOrderWhateverOrderTheyFinishIn) {
  // Early inputs take longest, so later reads finish first.
  ReadAhead<int, std::string> reads(Range(12), 4, [](const int& i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(3 * (12 - i) % 17));
    return std::to_string(i);
  });
  EXPECT_EQ(reads.size(), 12u);
  for (int i = 0; i < 12; ++i) {
    std::optional<std::string> result = reads.Next();
    ASSERT_TRUE(result.has_value()) << i;
    EXPECT_EQ(*result, std::to_string(i));
  }
  EXPECT_FALSE(reads.Next().has_value());
  EXPECT_FALSE(reads.Next().has_value());
}

TEST(ReadAhead, KeepsAtMostItsDepthRunningAndUsesIt) {
  std::atomic<int> running{0};
  std::atomic<int> most{0};
  ReadAhead<int, int> reads(Range(40), 5, [&](const int& i) {
    const int now = ++running;
    for (int seen = most.load(); now > seen && !most.compare_exchange_weak(seen, now);) {
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    --running;
    return i * i;
  });
  int count = 0;
  while (std::optional<int> result = reads.Next()) {
    EXPECT_EQ(*result, count * count);
    ++count;
  }
  EXPECT_EQ(count, 40);
  EXPECT_LE(most.load(), 5);
  EXPECT_GE(most.load(), 2);  // reads did overlap
}

TEST(ReadAhead, DepthOneReadsOnTheCallersThreadOneAtATime) {
  const std::thread::id caller = std::this_thread::get_id();
  int started = 0;
  ReadAhead<int, int> reads(Range(3), 1, [&](const int& i) {
    EXPECT_EQ(std::this_thread::get_id(), caller);
    ++started;
    return i;
  });
  EXPECT_EQ(started, 0);  // nothing runs before it is asked for
  EXPECT_EQ(reads.Next(), 0);
  EXPECT_EQ(started, 1);
  EXPECT_EQ(reads.Next(), 1);
  EXPECT_EQ(reads.Next(), 2);
  EXPECT_FALSE(reads.Next().has_value());
}

TEST(ReadAhead, AReadsErrorThrowsWhereItsResultWouldComeOut) {
  for (std::size_t depth : {1u, 3u}) {
    ReadAhead<int, int> reads(Range(6), depth, [](const int& i) {
      if (i == 2) throw std::runtime_error("block 2 is damaged");
      return i;
    });
    EXPECT_EQ(reads.Next(), 0) << depth;
    EXPECT_EQ(reads.Next(), 1) << depth;
    try {
      reads.Next();
      ADD_FAILURE() << "no error at depth " << depth;
    } catch (const std::runtime_error& e) {
      EXPECT_STREQ(e.what(), "block 2 is damaged");
    }
  }
}

TEST(ReadAhead, AbandonedWithReadsRunningWaitsForThem) {
  std::atomic<int> finished{0};
  {
    ReadAhead<int, int> reads(Range(10), 4, [&](const int& i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      ++finished;
      return i;
    });
    EXPECT_EQ(reads.Next(), 0);
  }
  // The first and the three read ahead with it ran to their end; no more started.
  EXPECT_EQ(finished.load(), 4);
}

}  // namespace
}  // namespace octocosm
