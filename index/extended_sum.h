// The sum of doubles in extended precision (long double: the x87 80-bit
// format on x86-64), in index order, where a total must come out the same
// whatever the values' magnitudes: the sampler's and the block codec's
// weight totals.
#pragma once

#include <span>

namespace octocosm {

// Not inline on purpose (index/extended_sum.cc): inlined into a loop that
// also computes the values, GCC kept the x87 sum in memory, a store and a
// reload for every value (a fifth of EncodeBlock's time, and of
// SampleNode's).
long double ExtendedSum(std::span<const double> values);

}  // namespace octocosm
