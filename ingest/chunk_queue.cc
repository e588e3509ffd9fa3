#include "ingest/chunk_queue.h"

#include <algorithm>
#include <utility>

namespace octocosm {

ChunkQueue::ChunkQueue(std::vector<std::uint64_t> point_counts, std::size_t window)
    : point_counts_(std::move(point_counts)), window_(std::max<std::size_t>(window, 1)), taken_(point_counts_.size()) {}

std::size_t ChunkQueue::Take() {
  const std::size_t none = point_counts_.size();
  MutexLock lock(mutex_);
  while (first_open_ < none && taken_[first_open_]) ++first_open_;
  const std::size_t end = std::min(none, first_open_ + window_);
  std::size_t best = none;
  for (std::size_t c = first_open_; c < end; ++c) {
    if (!taken_[c] && (best == none || point_counts_[c] > point_counts_[best])) best = c;
  }
  if (best != none) taken_[best] = true;
  return best;
}

}  // namespace octocosm
