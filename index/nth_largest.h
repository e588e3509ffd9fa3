// The value of a given rank among many doubles: a priority sampler's
// threshold (index/sampler.h), where a parent keeps up to 16000 points of a
// population of up to eight times that.
//
// std::nth_element over all values partitions them several times. Instead,
// counting the rank from the nearer end (from the largest or from the
// smallest), a bound is read off an evenly spaced sample of 1024 values,
// far enough out that nearly always more values than the rank reach it (the
// rank's expected place in the sample, moved out by four standard deviations
// and some), and the selection runs among the values that reach it only: one
// branch-free pass over all values, then a selection among at most about
// half of them. The answer is exact either way: when too few values reach
// the bound (a sample that happens to hold more of the extreme values than
// their share), the selection runs among all of them. Measured against
// std::nth_element over a copy (lognormal values, rank 16000, one thread):
// 95-117 against 196-227 us for 20000 values, 222-231 against 411-421 us
// for 40000, 325-329 against 1134-1176 us for 128000.
#pragma once

#include <cstddef>
#include <span>

namespace octocosm {

// The value of rank `rank` among `values`, 0 being the largest: the value
// std::nth_element with std::greater would put at position `rank`. Requires
// rank < values.size(); the values must not be NaN.
double NthLargest(std::span<const double> values, std::size_t rank);

}  // namespace octocosm
