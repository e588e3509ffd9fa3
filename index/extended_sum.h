// The sum of doubles in extended precision (long double: the x87 80-bit
// format on x86-64), where a total must come out the same whatever the
// values' magnitudes: the sampler's and the block codec's weight totals. The
// order of the additions is fixed (value i goes to running sum i mod 4 while
// four remain, the rest to the first; then (s0 + s1) + (s2 + s3)), so the
// same values in the same order always give the same total.
#pragma once

#include <span>

namespace octocosm {

// Not inline on purpose (index/extended_sum.cc): inlined into a loop that
// also computes the values, GCC kept the x87 sum in memory, a store and a
// reload for every value (a fifth of EncodeBlock's time, and of
// SampleNode's).
long double ExtendedSum(std::span<const double> values);

}  // namespace octocosm
