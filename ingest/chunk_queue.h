// Hands out an ingest's chunks to its build threads: the largest not yet
// taken among the `window` chunks (in depth-first order) from the first not
// yet taken.
//
// Why not strictly in order: then the last chunk was any size, and the other
// threads idled while one built it; from the first thread's end to the
// last's, 34 ms on average at 10^7 points in 64 chunks (eight runs), 23 ms
// with a window of 8 chunks, 28 ms with 4, 25 with 16. (For an epoch held in
// memory whole, Chunker::SplitTail also cuts the last chunks smaller.)
//
// Why a window of places: the merger takes the chunks' roots in depth-first
// order, so a root that completes early waits in memory for those before it.
// Every chunk taken lies less than `window` places past the first not taken,
// so at most `window` - 1 roots wait for that one (plus one a thread for
// those being built). A window counted in chunks not yet taken instead
// passed over a small chunk again and again while larger ones came into
// view, and every later root waited for it: a peak RSS of 588 MiB at 10^7
// points under a 64 MiB budget in the bench (124 MiB with a window of places).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "base/mutex.h"

namespace octocosm {

class ChunkQueue {
 public:
  // `point_counts[c]` is chunk c's size; window 0 counts as 1 (strict order).
  ChunkQueue(std::vector<std::uint64_t> point_counts, std::size_t window);

  // The chunk to build next, or point_counts.size() once all are taken.
  // Thread-safe.
  std::size_t Take() EXCLUDES(mutex_);

 private:
  const std::vector<std::uint64_t> point_counts_;
  const std::size_t window_;
  Mutex mutex_;
  std::vector<bool> taken_ GUARDED_BY(mutex_);
  std::size_t first_open_ GUARDED_BY(mutex_) = 0;
};

}  // namespace octocosm
