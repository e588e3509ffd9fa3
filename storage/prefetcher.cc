#include "storage/prefetcher.h"

#include <sstream>
#include <utility>

#include "storage/read_cancellation.h"

namespace octocosm {

namespace {

std::string DescribeBlock(const BlockId& id) {
  std::ostringstream out;
  out << "block (epoch " << id.epoch << ", key 0x" << std::hex << id.key << ")";
  return out.str();
}

// A copy of `error` that shares no message buffer with it: errors_ is read
// by other threads, and libstdc++'s reference count on a runtime_error's
// message is invisible to ThreadSanitizer (see block_cache.cc).
Error ThreadOwnCopy(const Error& error) { return Error(error.kind(), error.what()); }

}  // namespace

std::string PrefetchStats::ToString() const {
  std::ostringstream out;
  out << "prefetch: " << workers << " workers, queue " << queue_depth << ", in flight "
      << in_flight << ", hits " << hits << ", queued " << queued << ", completed " << completed
      << ", found resident " << found_resident << ", failed " << failed << ", cancelled "
      << cancelled;
  if (callback_errors > 0) out << ", callback errors " << callback_errors;
  return out.str();
}

Prefetcher::Prefetcher(BlockCache& cache) : Prefetcher(cache, Options{}) {}

Prefetcher::Prefetcher(BlockCache& cache, Options options)
    : cache_(cache), on_complete_(std::move(options.on_complete)) {
  if (options.workers == 0) {
    throw Error::InvalidArgument("prefetcher needs at least one worker thread");
  }
  stats_.workers = options.workers;
  workers_.reserve(options.workers);
  try {
    for (std::size_t i = 0; i < options.workers; ++i) {
      workers_.emplace_back([this] { WorkerLoop(); });
    }
  } catch (...) {
    // The destructor does not run for a half-built object: stop the workers
    // already started, or joining them would wait forever.
    {
      MutexLock lock(mutex_);
      stopping_ = true;
    }
    work_cv_.SignalAll();
    workers_.clear();
    throw;
  }
}

Prefetcher::~Prefetcher() {
  {
    MutexLock lock(mutex_);
    stopping_ = true;
    stats_.cancelled += queue_.size();
    queue_.clear();
    pending_.clear();
    for (auto& [id, cancelled] : in_flight_) cancelled->store(true, std::memory_order_relaxed);
  }
  work_cv_.SignalAll();
  idle_cv_.SignalAll();
  workers_.clear();  // joins; reads in flight finish first
}

void Prefetcher::QueueLocked(const BlockId& id, Priority priority) {
  auto position = queue_.emplace(QueueKey{priority, next_sequence_++}, id).first;
  pending_.insert_or_assign(id, position);
}

std::size_t Prefetcher::Submit(std::span<const BlockId> wanted) {
  std::size_t depth = 0;
  {
    MutexLock lock(mutex_);
    // The new queue is built in `next`, reusing the nodes of requests that
    // stay wanted, so a frame that re-asks for mostly the same blocks
    // allocates only for the new ones. Whatever is left in queue_ afterwards
    // is no longer wanted.
    Queue next;
    const std::uint64_t first_sequence_of_this_call = next_sequence_;
    std::unordered_set<BlockId, BlockIdHash> resident;  // so a duplicate is one hit
    // Walk from least to most important: resident blocks are touched in that
    // order, so the most important ends up most recent in the LRU; and a block
    // listed twice is re-ranked to its first position when that is reached.
    for (std::size_t rank = wanted.size(); rank-- > 0;) {
      const BlockId& id = wanted[rank];
      const QueueKey key{static_cast<Priority>(rank), next_sequence_++};
      if (auto it = pending_.find(id); it != pending_.end()) {
        const bool placed_by_this_call = it->second->first.sequence >= first_sequence_of_this_call;
        auto node = (placed_by_this_call ? next : queue_).extract(it->second);
        node.key() = key;
        it->second = next.insert(std::move(node)).position;
      } else if (in_flight_.contains(id) || resident.contains(id)) {
        continue;
      } else if (cache_.Touch(id)) {
        resident.insert(id);
        ++stats_.hits;
      } else {
        ++stats_.queued;
        pending_.emplace(id, next.emplace(key, id).first);
      }
    }
    for (const auto& [key, id] : queue_) pending_.erase(id);
    stats_.cancelled += queue_.size();
    // Reads no longer wanted stop; a read wanted again goes on if it has not
    // stopped yet (else the next Submit queues it again).
    if (!in_flight_.empty()) {
      const std::unordered_set<BlockId, BlockIdHash> still_wanted(wanted.begin(), wanted.end());
      for (auto& [id, cancelled] : in_flight_) cancelled->store(!still_wanted.contains(id), std::memory_order_relaxed);
    }
    queue_ = std::move(next);
    depth = queue_.size();
  }
  if (depth > 0) work_cv_.SignalAll();
  idle_cv_.SignalAll();  // cancellations may end a WaitFor() or Drain()
  return depth;
}

bool Prefetcher::Add(const BlockId& id, Priority priority) {
  {
    MutexLock lock(mutex_);
    if (auto reading = in_flight_.find(id); reading != in_flight_.end()) {
      reading->second->store(false, std::memory_order_relaxed);  // wanted after all, if not stopped yet
      return false;
    }
    if (auto it = pending_.find(id); it != pending_.end()) {
      queue_.erase(it->second);
      QueueLocked(id, priority);
      return true;
    }
    if (cache_.Touch(id)) {
      ++stats_.hits;
      return false;
    }
    ++stats_.queued;
    QueueLocked(id, priority);
  }
  work_cv_.Signal();
  return true;
}

bool Prefetcher::Cancel(const BlockId& id) {
  {
    MutexLock lock(mutex_);
    if (auto reading = in_flight_.find(id); reading != in_flight_.end()) {
      reading->second->store(true, std::memory_order_relaxed);
    }
    auto it = pending_.find(id);
    if (it == pending_.end()) return false;
    queue_.erase(it->second);
    pending_.erase(it);
    ++stats_.cancelled;
  }
  idle_cv_.SignalAll();
  return true;
}

std::size_t Prefetcher::CancelAll() {
  std::size_t dropped = 0;
  {
    MutexLock lock(mutex_);
    dropped = queue_.size();
    for (auto& [reading, cancelled] : in_flight_) cancelled->store(true, std::memory_order_relaxed);
    queue_.clear();
    pending_.clear();
    stats_.cancelled += dropped;
  }
  idle_cv_.SignalAll();
  return dropped;
}

void Prefetcher::WaitFor(const BlockId& id) {
  MutexLock lock(mutex_);
  while (pending_.contains(id) || in_flight_.contains(id)) idle_cv_.Wait(mutex_);
}

void Prefetcher::Drain() {
  MutexLock lock(mutex_);
  while (!queue_.empty() || !in_flight_.empty()) idle_cv_.Wait(mutex_);
}

std::optional<Error> Prefetcher::LastError(const BlockId& id) const {
  MutexLock lock(mutex_);
  auto it = errors_.find(id);
  if (it == errors_.end()) return std::nullopt;
  return ThreadOwnCopy(it->second);
}

PrefetchStats Prefetcher::Stats() const {
  MutexLock lock(mutex_);
  PrefetchStats snapshot = stats_;
  snapshot.queue_depth = queue_.size();
  snapshot.in_flight = in_flight_.size();
  return snapshot;
}

void Prefetcher::WorkerLoop() {
  MutexLock lock(mutex_);
  while (true) {
    while (!stopping_ && queue_.empty()) work_cv_.Wait(mutex_);
    if (stopping_) return;
    const BlockId id = queue_.begin()->second;
    queue_.erase(queue_.begin());
    pending_.erase(id);
    const auto cancelled = std::make_shared<std::atomic<bool>>(false);
    in_flight_.emplace(id, cancelled);
    lock.Unlock();

    bool was_resident = false;
    bool stopped = false;  // cancelled while read
    std::optional<Error> error;
    try {
      const ReadCancellationScope scope(cancelled.get());
      // The handle Get() returns is dropped at once: prefetched blocks wait
      // in the cache unpinned.
      was_resident = cache_.Touch(id);
      if (!was_resident) cache_.Get(id);
    } catch (const Error& e) {
      stopped = cancelled->load(std::memory_order_relaxed);
      if (!stopped) error = ThreadOwnCopy(e);
    } catch (const std::exception& e) {
      // A BlockSource should throw only Error; keep anything else (e.g.
      // bad_alloc) from escaping the thread, which would terminate.
      error = Error(ErrorKind::kIo, "prefetch of " + DescribeBlock(id) + " failed: " + e.what());
    } catch (...) {
      error = Error(ErrorKind::kIo, "prefetch of " + DescribeBlock(id) +
                                        " failed with an exception that is not a std::exception");
    }

    bool callback_threw = false;
    if (on_complete_ && !stopped) {
      try {
        on_complete_(id, error ? &*error : nullptr);
      } catch (...) {
        callback_threw = true;
      }
    }

    lock.Lock();
    in_flight_.erase(id);
    if (stopped) {
      ++stats_.cancelled;
    } else if (error) {
      ++stats_.failed;
      errors_.insert_or_assign(id, ThreadOwnCopy(*error));
    } else {
      ++(was_resident ? stats_.found_resident : stats_.completed);
      errors_.erase(id);
    }
    if (callback_threw) ++stats_.callback_errors;
    idle_cv_.SignalAll();
  }
}

}  // namespace octocosm
