// Prefetcher: a pool of worker threads that read blocks into a BlockCache
// ahead of need, most important first.
//
// The intended caller is a renderer that, each frame, knows the blocks it
// wants in order of importance. It hands the whole list to Submit(), which
// REPLACES the pending queue: blocks no longer wanted are cancelled (if a
// worker is reading one from a server, its transfer stops:
// storage/read_cancellation.h), blocks still wanted are re-ranked, blocks
// already resident are skipped (counted as hits), and blocks being read stay
// in flight. Single requests can also be added with Add(), and withdrawn with
// Cancel() / CancelAll().
//
// Priority. A lower Priority value is more important. Submit() ranks its list
// 0, 1, 2, ... in list order; Add() takes an explicit value on the same scale.
// Workers always take the pending request with the lowest value; equal values
// are taken in the order they were queued.
//
// Coalescing. Where the cache's source says that reading neighbouring blocks
// together pays (a store on a server: BlockSource::CoalescesReads), a worker
// that takes a request also takes the pending requests, among the next most
// important, for blocks near it in the same file (storage/read_coalescing.h)
// and reads them with one request (BlockCache::Load). Such a read stops only
// when none of its blocks is wanted any more; when it fails, its blocks are
// read one at a time, so that each error is its own block's.
//
// Completion. A worker reads through BlockCache::Get() (so a prefetch and a
// foreground Get() of the same block share one read) and releases its handle
// at once: finished blocks sit in the cache unpinned, subject to LRU eviction.
// The caller notices them by polling BlockCache::TryGet(), by the optional
// completion callback, or by WaitFor() / Drain().
//
// Errors. A failed read is never thrown from a worker: it is counted
// (PrefetchStats::failed), passed to the callback, and remembered per block
// until that block is later read successfully (LastError()).
//
// Concurrency. All public methods are thread-safe. Submit/Add/Cancel/
// CancelAll/Stats/LastError never block on I/O; WaitFor() and Drain() block
// until the named work is done. The destructor drops pending requests, stops
// reads in flight from a server, waits for the others to finish and joins
// the workers; the cache must outlive the Prefetcher.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "base/error.h"
#include "base/mutex.h"
#include "storage/block_cache.h"
#include "storage/block_source.h"

namespace octocosm {

struct PrefetchStats {
  std::size_t workers = 0;
  // Gauges.
  std::size_t queue_depth = 0;  // pending requests no worker has started
  std::size_t in_flight = 0;    // requests a worker is reading now
  // Counters over the Prefetcher's lifetime. Every queued request ends in
  // exactly one of completed, found_resident, failed, cancelled, so at any
  // snapshot
  //   queued == completed + found_resident + failed + cancelled + queue_depth + in_flight.
  std::uint64_t hits = 0;            // not queued: resident when asked for (once per call)
  std::uint64_t queued = 0;          // requests put on the queue (re-ranking one does not count)
  std::uint64_t completed = 0;       // read into the cache by a worker
  std::uint64_t found_resident = 0;  // resident by the time a worker started them
  std::uint64_t failed = 0;          // their read threw
  std::uint64_t cancelled = 0;       // dropped before a worker started them, or stopped while read
  std::uint64_t callback_errors = 0;  // completion callbacks that threw (swallowed)

  std::string ToString() const;
};

class Prefetcher {
 public:
  using Priority = std::int64_t;

  // Called on a worker thread once per request a worker finishes
  // (completed, found resident or failed; not for cancelled requests or for
  // ones skipped at submission as resident). `error` is null on success. It
  // runs before the request stops counting as in flight, so WaitFor()/Drain()
  // return after it. It must not call WaitFor() or Drain() (it would wait for itself) and
  // should not throw; an exception is swallowed and counted.
  using CompletionCallback = std::function<void(const BlockId& id, const Error* error)>;

  struct Options {
    std::size_t workers = 2;  // at least 1
    // Read blocks near one another together where the source coalesces
    // reads (above); off, every block is read alone.
    bool coalesce_reads = true;
    CompletionCallback on_complete;
  };

  // Throws InvalidArgument when options.workers is 0.
  explicit Prefetcher(BlockCache& cache);
  Prefetcher(BlockCache& cache, Options options);
  Prefetcher(const Prefetcher&) = delete;
  Prefetcher& operator=(const Prefetcher&) = delete;
  ~Prefetcher();

  // Replaces the pending queue with `wanted`, most important first (duplicates
  // keep their first position). Resident blocks are marked recently used in
  // the cache, least important first, so the most important are evicted last.
  // Returns how many requests are pending after the call.
  std::size_t Submit(std::span<const BlockId> wanted) EXCLUDES(mutex_);

  // Queues one request, or re-ranks it if already pending. Returns false when
  // nothing was queued because the block is resident or already in flight.
  bool Add(const BlockId& id, Priority priority) EXCLUDES(mutex_);

  // Drops a pending request, or stops one in flight from a server; returns
  // whether one was pending.
  bool Cancel(const BlockId& id) EXCLUDES(mutex_);

  // Drops every pending request and stops those in flight from a server;
  // returns how many were pending.
  std::size_t CancelAll() EXCLUDES(mutex_);

  // Blocks until `id` is neither pending nor in flight (at once if it never
  // was requested).
  void WaitFor(const BlockId& id) EXCLUDES(mutex_);

  // Blocks until the queue is empty and nothing is in flight. Requests added
  // by other threads meanwhile are waited for too.
  void Drain() EXCLUDES(mutex_);

  // The error of the block's most recent failed prefetch, if it has not been
  // read successfully since. One Error is kept per such block for the life of
  // the Prefetcher.
  std::optional<Error> LastError(const BlockId& id) const EXCLUDES(mutex_);

  PrefetchStats Stats() const EXCLUDES(mutex_);

 private:
  struct QueueKey {
    Priority priority;
    std::uint64_t sequence;  // tie-break: first queued is taken first
    friend auto operator<=>(const QueueKey&, const QueueKey&) = default;
  };
  using Queue = std::map<QueueKey, BlockId>;

  // One read by a worker: of one block, or of several near one another.
  struct Read {
    // Set while none of its blocks is wanted: a read from a server stops.
    std::atomic<bool> cancelled{false};
    std::size_t blocks = 0;    // guarded by mutex_
    std::size_t unwanted = 0;  // guarded by mutex_
  };
  struct InFlight {
    std::shared_ptr<Read> read;
    bool wanted = true;
  };
  // What became of one block a worker read.
  struct Outcome {
    bool was_resident = false;
    bool stopped = false;  // cancelled while read
    std::optional<Error> error;
  };
  // The pending requests looked at for blocks near the one a worker takes.
  static constexpr std::size_t kCoalesceCandidates = 512;

  void WorkerLoop() EXCLUDES(mutex_);
  // Puts `id` (not pending) on the queue.
  void QueueLocked(const BlockId& id, Priority priority) REQUIRES(mutex_);
  // Makes `id` (taken off the queue) one of the blocks of `read`.
  void JoinReadLocked(const BlockId& id, const std::shared_ptr<Read>& read) REQUIRES(mutex_);
  // Marks a block in flight wanted or not; its read is cancelled while none
  // of its blocks is wanted.
  void SetWantedLocked(InFlight& block, bool wanted) REQUIRES(mutex_);
  // The blocks of the next kCoalesceCandidates pending requests in `first`'s epoch.
  std::vector<BlockId> CandidatesLocked(const BlockId& first) const REQUIRES(mutex_);
  // Reads `blocks` (one read's) into the cache: together where there are
  // several, else (or when that fails) one at a time.
  std::vector<Outcome> ReadInto(std::span<const BlockId> blocks, const Read& read) EXCLUDES(mutex_);
  Outcome ReadOne(const BlockId& id, const Read& read) EXCLUDES(mutex_);

  BlockCache& cache_;
  const CompletionCallback on_complete_;

  mutable Mutex mutex_;
  CondVar work_cv_;  // a request was queued, or stopping_
  CondVar idle_cv_;  // a request left the queue or finished
  bool stopping_ GUARDED_BY(mutex_) = false;
  std::uint64_t next_sequence_ GUARDED_BY(mutex_) = 0;
  Queue queue_ GUARDED_BY(mutex_);
  std::unordered_map<BlockId, Queue::iterator, BlockIdHash> pending_ GUARDED_BY(mutex_);
  // Requests a worker is reading, each with its read.
  std::unordered_map<BlockId, InFlight, BlockIdHash> in_flight_ GUARDED_BY(mutex_);
  const bool coalesce_;  // the cache's source coalesces reads
  std::unordered_map<BlockId, Error, BlockIdHash> errors_ GUARDED_BY(mutex_);
  PrefetchStats stats_ GUARDED_BY(mutex_);
  // Last member: destroyed (joined) first, while everything above is alive.
  std::vector<std::jthread> workers_;
};

}  // namespace octocosm
