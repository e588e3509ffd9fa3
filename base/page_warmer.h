// Faults in the pages of freshly allocated memory on a background thread, so
// that the thread which fills that memory does not stop at each new page for
// the kernel to zero it. Pays where one thread fills a large buffer while a
// core is idle (the single-threaded read of a resident epoch): on a virtual
// machine whose host backs guest memory lazily, first touches cost about
// 2 s per GiB, a quarter of ingest's CPU time.
//
// Warming never changes the contents of the memory: it asks the kernel to
// populate pages for writing (MADV_POPULATE_WRITE, Linux 5.14), which leaves
// a page already present alone. Where the kernel lacks it, warming does
// nothing. A range freed while the warmer runs (a vector that outgrew its
// reservation) comes to no harm either: populating leaves contents alone,
// and an unmapped range ends the warming.
#pragma once

#include <cstddef>
#include <thread>
#include <vector>

namespace octocosm {

class PageWarmer {
 public:
  struct Range {
    const void* begin;
    std::size_t bytes;
  };

  // Starts warming `ranges`, slices of each in turn, so that ranges which are
  // filled side by side (the columns of one buffer) are warmed side by side.
  explicit PageWarmer(std::vector<Range> ranges);
  ~PageWarmer();  // Stop(): the filler is done, so the rest would be waste

  PageWarmer(const PageWarmer&) = delete;
  PageWarmer& operator=(const PageWarmer&) = delete;

  // Asks the thread to finish after its current slice and waits for it.
  void Stop();
  // Waits until every range is warmed.
  void Wait();

  // How many bytes the kernel populated, once Stop or Wait has returned.
  std::size_t warmed_bytes() const { return warmed_bytes_; }

 private:
  void Run(std::stop_token stop, std::vector<Range> ranges);

  std::size_t warmed_bytes_ = 0;
  std::jthread thread_;
};

}  // namespace octocosm
