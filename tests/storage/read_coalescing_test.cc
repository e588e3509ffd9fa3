// Which blocks join a read: one run around the first block, gaps and span
// within their limits, in the file's order.
#include "storage/read_coalescing.h"

#include <gtest/gtest.h>

#include <vector>

namespace octocosm {
namespace {

CoalesceLimits Limits(std::uint64_t gap, std::uint64_t span) {
  CoalesceLimits limits;
  limits.max_gap_bytes = gap;
  limits.max_span_bytes = span;
  return limits;
}

TEST(CoalesceAround, TakesNeighboursOnBothSidesInFileOrder) {
  // first: [1000, 1100)
  const std::vector<BlockExtent> candidates = {
      {1300, 100},  // 0: gap 100 after a right neighbour
      {1100, 100},  // 1: adjacent on the right
      {850, 100},   // 2: gap 50 on the left
      {5000, 10},   // 3: far away
  };
  EXPECT_EQ(CoalesceAround({1000, 100}, candidates, Limits(100, 1 << 20)), (std::vector<std::size_t>{2, 1, 0}));
  // A gap of 100 is too much at 99: the run stops at the first such gap.
  EXPECT_EQ(CoalesceAround({1000, 100}, candidates, Limits(99, 1 << 20)), (std::vector<std::size_t>{2, 1}));
  EXPECT_EQ(CoalesceAround({1000, 100}, candidates, Limits(0, 1 << 20)), (std::vector<std::size_t>{1}));
}

TEST(CoalesceAround, TheSpanIsBounded) {
  const std::vector<BlockExtent> candidates = {{100, 100}, {200, 100}, {0, 100}};
  // first [300, 400): the run may reach back to 100 within a span of 300.
  EXPECT_EQ(CoalesceAround({300, 100}, candidates, Limits(0, 300)), (std::vector<std::size_t>{0, 1}));
  EXPECT_EQ(CoalesceAround({300, 100}, candidates, Limits(0, 400)), (std::vector<std::size_t>{2, 0, 1}));
  // A first block larger than the span takes nothing.
  EXPECT_TRUE(CoalesceAround({300, 1000}, candidates, Limits(1000, 500)).empty());
}

TEST(CoalesceAround, OverlappingCandidatesAreLeftOut) {
  const std::vector<BlockExtent> candidates = {{1050, 100}, {1100, 50}, {950, 100}, {900, 100}};
  // [1050, 1150) and [950, 1050) overlap first [1000, 1100); [1100, 1150)
  // and [900, 1000) touch it.
  EXPECT_EQ(CoalesceAround({1000, 100}, candidates, Limits(0, 1 << 20)), (std::vector<std::size_t>{3, 1}));
}

TEST(CoalesceAround, NoCandidatesNoRun) {
  EXPECT_TRUE(CoalesceAround({0, 10}, {}, Limits(100, 100)).empty());
}

}  // namespace
}  // namespace octocosm
