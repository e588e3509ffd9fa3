// Splits [0, count) into one contiguous range per thread and runs
// body(begin, end) on each, the calling thread taking the first range. The
// split depends only on count and threads, so a body whose ranges do not
// interact gives the same result for any thread count. An exception thrown
// by a body is rethrown on the calling thread after all ranges finish.
#pragma once

#include <cstddef>
#include <functional>

namespace octocosm::synth {

void ParallelFor(std::size_t count, int threads, const std::function<void(std::size_t, std::size_t)>& body);

// The thread count to use for `requested` (0 means all hardware threads).
int ResolveThreadCount(int requested);

}  // namespace octocosm::synth
