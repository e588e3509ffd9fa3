// Splits [0, count) into one contiguous range per thread and runs
// body(begin, end) on each, the calling thread taking the first range. The
// split depends only on count and threads, so a body whose ranges do not
// interact gives the same result for any thread count. An exception thrown
// by a body is rethrown on the calling thread after all ranges finish.
#pragma once

#include <cstddef>
#include <functional>

namespace octocosm {

// min_items_per_thread keeps light loops on fewer threads, where starting a
// thread would cost more than it saves.
void ParallelFor(std::size_t count, int threads, const std::function<void(std::size_t, std::size_t)>& body,
                 std::size_t min_items_per_thread = 4096);

// The thread count to use for `requested` (0 means all hardware threads).
int ResolveThreadCount(int requested);

}  // namespace octocosm
