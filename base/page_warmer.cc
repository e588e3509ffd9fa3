#include "base/page_warmer.h"

#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>

#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23  // Linux 5.14; older C libraries lack the name
#endif

namespace octocosm {
namespace {

// Slices small enough that the filler rarely overtakes the warmer by much,
// large enough that a slice is one system call of many huge pages.
constexpr std::size_t kSliceBytes = std::size_t{16} << 20;

}  // namespace

PageWarmer::PageWarmer(std::vector<Range> ranges)
    : thread_([this](std::stop_token stop, std::vector<Range> owned) { Run(stop, std::move(owned)); },
              std::move(ranges)) {}

PageWarmer::~PageWarmer() { Stop(); }

void PageWarmer::Stop() {
  if (!thread_.joinable()) return;
  thread_.request_stop();
  thread_.join();
}

void PageWarmer::Wait() {
  if (thread_.joinable()) thread_.join();
}

void PageWarmer::Run(std::stop_token stop, std::vector<Range> ranges) {
  const long page_size = sysconf(_SC_PAGESIZE);
  if (page_size <= 0) return;
  const auto page = static_cast<std::uintptr_t>(page_size);
  // Whole pages inside each range: a page shared with other memory is left
  // to whoever touches it (populating it would be harmless, but not ours).
  std::size_t largest = 0;
  for (Range& range : ranges) {
    const auto begin = reinterpret_cast<std::uintptr_t>(range.begin);
    const std::uintptr_t first = (begin + page - 1) / page * page;
    const std::uintptr_t last = (begin + range.bytes) / page * page;
    range = {reinterpret_cast<const void*>(first), last > first ? last - first : 0};
    largest = std::max(largest, range.bytes);
  }
  if (largest == 0) return;
  // Each range advances by its share of one slice, so all finish together.
  const std::size_t steps = (largest + kSliceBytes - 1) / kSliceBytes;
  for (std::size_t step = 0; step < steps; ++step) {
    for (const Range& range : ranges) {
      if (stop.stop_requested()) return;
      const std::size_t share = (range.bytes / page + steps - 1) / steps * page;
      const std::size_t offset = step * share;
      if (share == 0 || offset >= range.bytes) continue;
      const std::size_t bytes = std::min(share, range.bytes - offset);
      auto* begin = const_cast<char*>(static_cast<const char*>(range.begin)) + offset;
      if (madvise(begin, bytes, MADV_POPULATE_WRITE) != 0) return;  // not supported: nothing to gain
      warmed_bytes_ += bytes;
    }
  }
}

}  // namespace octocosm
