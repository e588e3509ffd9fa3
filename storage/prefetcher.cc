#include "storage/prefetcher.h"

#include <sstream>
#include <utility>

#include "storage/read_cancellation.h"
#include "storage/read_coalescing.h"

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

// Those of `candidates` whose blocks lie near `first`'s (CoalesceAround).
// Locating a block may read its epoch's index; a failure to locate leaves
// the block out (its own read reports it).
std::vector<BlockId> Neighbours(const BlockSource& source, const BlockId& first,
                                std::span<const BlockId> candidates) {
  try {
    const std::optional<BlockExtent> first_extent = source.Locate(first);
    if (!first_extent) return {};
    std::vector<BlockId> located;
    std::vector<BlockExtent> extents;
    for (const BlockId& id : candidates) {
      if (std::optional<BlockExtent> extent = source.Locate(id)) {
        located.push_back(id);
        extents.push_back(*extent);
      }
    }
    std::vector<BlockId> near;
    for (std::size_t i : CoalesceAround(*first_extent, extents)) near.push_back(located[i]);
    return near;
  } catch (...) {
    return {};
  }
}

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
    : cache_(cache),
      on_complete_(std::move(options.on_complete)),
      coalesce_(options.coalesce_reads && cache.source() != nullptr && cache.source()->CoalescesReads()) {
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
    for (auto& [id, block] : in_flight_) SetWantedLocked(block, false);
  }
  work_cv_.SignalAll();
  idle_cv_.SignalAll();
  workers_.clear();  // joins; reads in flight finish first
}

void Prefetcher::QueueLocked(const BlockId& id, Priority priority) {
  auto position = queue_.emplace(QueueKey{priority, next_sequence_++}, id).first;
  pending_.insert_or_assign(id, position);
}

void Prefetcher::JoinReadLocked(const BlockId& id, const std::shared_ptr<Read>& read) {
  ++read->blocks;
  in_flight_.insert_or_assign(id, InFlight{read, true});
  read->cancelled.store(read->unwanted == read->blocks, std::memory_order_relaxed);
}

void Prefetcher::SetWantedLocked(InFlight& block, bool wanted) {
  if (block.wanted == wanted) return;
  block.wanted = wanted;
  Read& read = *block.read;
  if (wanted) {
    --read.unwanted;
  } else {
    ++read.unwanted;
  }
  read.cancelled.store(read.unwanted == read.blocks, std::memory_order_relaxed);
}

std::vector<BlockId> Prefetcher::CandidatesLocked(const BlockId& first) const {
  std::vector<BlockId> candidates;
  std::size_t looked_at = 0;
  for (auto it = queue_.begin(); it != queue_.end() && looked_at < kCoalesceCandidates; ++it, ++looked_at) {
    if (it->second.epoch == first.epoch) candidates.push_back(it->second);
  }
  return candidates;
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
    // Blocks wanted again are marked before those no longer wanted, so that
    // a read of several never looks unwanted on the way.
    if (!in_flight_.empty()) {
      const std::unordered_set<BlockId, BlockIdHash> still_wanted(wanted.begin(), wanted.end());
      for (auto& [id, block] : in_flight_) {
        if (still_wanted.contains(id)) SetWantedLocked(block, true);
      }
      for (auto& [id, block] : in_flight_) {
        if (!still_wanted.contains(id)) SetWantedLocked(block, false);
      }
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
      SetWantedLocked(reading->second, true);  // wanted after all, if not stopped yet
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
    if (auto reading = in_flight_.find(id); reading != in_flight_.end()) SetWantedLocked(reading->second, false);
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
    for (auto& [id, block] : in_flight_) SetWantedLocked(block, false);
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
    std::vector<BlockId> blocks{queue_.begin()->second};
    queue_.erase(queue_.begin());
    pending_.erase(blocks.front());
    const auto read = std::make_shared<Read>();
    JoinReadLocked(blocks.front(), read);
    if (coalesce_) {
      const std::vector<BlockId> candidates = CandidatesLocked(blocks.front());
      if (!candidates.empty()) {
        lock.Unlock();
        const std::vector<BlockId> near = Neighbours(*cache_.source(), blocks.front(), candidates);
        lock.Lock();
        // Other workers may have taken some meanwhile, or Submit dropped them.
        for (const BlockId& id : near) {
          auto it = pending_.find(id);
          if (it == pending_.end()) continue;
          queue_.erase(it->second);
          pending_.erase(it);
          JoinReadLocked(id, read);
          blocks.push_back(id);
        }
      }
    }
    lock.Unlock();

    const std::vector<Outcome> outcomes = ReadInto(blocks, *read);

    std::vector<bool> callback_threw(blocks.size(), false);
    if (on_complete_) {
      for (std::size_t i = 0; i < blocks.size(); ++i) {
        if (outcomes[i].stopped) continue;
        try {
          on_complete_(blocks[i], outcomes[i].error ? &*outcomes[i].error : nullptr);
        } catch (...) {
          callback_threw[i] = true;
        }
      }
    }

    lock.Lock();
    for (std::size_t i = 0; i < blocks.size(); ++i) {
      const BlockId& id = blocks[i];
      const Outcome& outcome = outcomes[i];
      in_flight_.erase(id);
      if (outcome.stopped) {
        ++stats_.cancelled;
      } else if (outcome.error) {
        ++stats_.failed;
        errors_.insert_or_assign(id, ThreadOwnCopy(*outcome.error));
      } else {
        ++(outcome.was_resident ? stats_.found_resident : stats_.completed);
        errors_.erase(id);
      }
      if (callback_threw[i]) ++stats_.callback_errors;
    }
    idle_cv_.SignalAll();
  }
}

std::vector<Prefetcher::Outcome> Prefetcher::ReadInto(std::span<const BlockId> blocks, const Read& read) {
  std::vector<Outcome> outcomes(blocks.size());
  std::vector<bool> loaded(blocks.size(), false);
  if (blocks.size() > 1) {
    try {
      const ReadCancellationScope scope(&read.cancelled);
      loaded = cache_.Load(blocks);
    } catch (...) {
      // Stopped: so is every block of it. Failed: each block is read alone
      // below, and tells its own error.
      if (read.cancelled.load(std::memory_order_relaxed)) {
        for (Outcome& outcome : outcomes) outcome.stopped = true;
        return outcomes;
      }
    }
  }
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    if (!loaded[i]) outcomes[i] = ReadOne(blocks[i], read);
  }
  return outcomes;
}

Prefetcher::Outcome Prefetcher::ReadOne(const BlockId& id, const Read& read) {
  Outcome outcome;
  try {
    const ReadCancellationScope scope(&read.cancelled);
    // The handle Get() returns is dropped at once: prefetched blocks wait
    // in the cache unpinned.
    outcome.was_resident = cache_.Touch(id);
    if (!outcome.was_resident) cache_.Get(id);
  } catch (const Error& e) {
    outcome.stopped = read.cancelled.load(std::memory_order_relaxed);
    if (!outcome.stopped) outcome.error = ThreadOwnCopy(e);
  } catch (const std::exception& e) {
    // A BlockSource should throw only Error; keep anything else (e.g.
    // bad_alloc) from escaping the thread, which would terminate.
    outcome.error = Error(ErrorKind::kIo, "prefetch of " + DescribeBlock(id) + " failed: " + e.what());
  } catch (...) {
    outcome.error = Error(ErrorKind::kIo, "prefetch of " + DescribeBlock(id) +
                                              " failed with an exception that is not a std::exception");
  }
  return outcome;
}

}  // namespace octocosm
