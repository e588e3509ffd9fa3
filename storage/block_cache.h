// BlockCache: an in-memory LRU cache of verified blocks with a budget in
// bytes, pinning of blocks in use, and single-flight read-through.
//
// Design (after LevelDB's util/cache.cc). Every resident entry is on exactly
// one of two lists:
//   - in_use_: entries pinned by at least one live PinnedBlock handle, in no
//     particular order. These are never evicted.
//   - lru_:    entries with no handle, least recently used first. Eviction
//     takes from the front.
// An entry moves to in_use_ when the first handle is taken and back to the
// most-recent end of lru_ when the last handle is released. An entry removed
// by Erase()/Clear()/replacement while pinned moves to a third list,
// detached_: no longer findable or charged to the budget, it lives until its
// last handle is released. Lists are std::list so that moving an entry is a
// splice and iterators held by handles stay valid.
//
// Budget. Each entry is charged its byte size plus kEntryOverheadBytes (a
// fixed estimate of the bookkeeping per entry, so that many tiny or empty
// blocks cannot grow the cache without bound). After every operation
//
//     resident_bytes <= max(capacity_bytes, pinned_bytes)
//
// i.e. the cache exceeds its budget only when the pinned entries alone exceed
// it, and returns within budget as soon as enough handles are released
// (release evicts unpinned entries immediately). A block larger than the whole
// budget can still be read and pinned; it is evicted when its last handle goes.
//
// Concurrency. All methods are thread-safe; one mutex guards the state and is
// never held while reading from the source. Get() blocks the caller for the
// duration of a source read (its own, or one already in flight for the same
// block: concurrent misses for one block read it once, and all waiters get the
// same bytes or an Error of the same kind and message). Other methods do not
// block on I/O.
//
// Recycled buffers. When an unpinned block is evicted and nobody shares its
// bytes, its buffer is kept (at most kMaxSpareBuffers of them, outside the
// budget) and handed to the source for the next read: touching fresh memory
// for every block costs a page fault per 4 KiB, which on virtual machines
// costs more than reading the block from disk.
//
// Ownership. The cache does not own the source, which must outlive it. Every
// PinnedBlock must be released (destroyed or Release()d) before the cache is
// destroyed; the bytes themselves can outlive the cache through
// PinnedBlock::Share().
#pragma once

#include <cstddef>
#include <cstdint>
#include <exception>
#include <list>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "base/error.h"
#include "base/mutex.h"
#include "storage/block_source.h"

namespace octocosm {

class PinnedBlock;

// A snapshot of the cache counters, taken under the cache lock so that the
// gauges (resident, pinned, entries) agree with each other.
struct CacheStats {
  std::size_t capacity_bytes = 0;
  // Lookups: every Get() and TryGet() is exactly one hit or one miss. A Get()
  // that joins a read already in flight is a miss that did not read.
  std::uint64_t hits = 0;
  std::uint64_t misses = 0;
  // Blocks read from the source: a ReadBlock call, or a block of a
  // ReadBlocks call (Load()).
  std::uint64_t source_reads = 0;    // started (successful or not)
  std::uint64_t read_failures = 0;   // whose call threw (not counting cancelled ones)
  std::uint64_t bytes_read = 0;      // returned by successful calls
  std::uint64_t inserts = 0;         // entries added, by Insert() or by a read
  std::uint64_t evictions = 0;       // entries dropped to stay within budget
  // Gauges (charges include kEntryOverheadBytes per entry).
  std::size_t resident_bytes = 0;    // charge of all findable entries, pinned or not
  std::size_t pinned_bytes = 0;      // charge of findable entries with a live handle
  std::size_t entries = 0;
  std::size_t pinned_entries = 0;
  std::size_t reads_in_flight = 0;

  std::uint64_t lookups() const { return hits + misses; }
  // One line, e.g. for a log or a HUD.
  std::string ToString() const;
};

class BlockCache {
 public:
  // Fixed charge per entry on top of its bytes: roughly the list node, the
  // hash-table node and the shared_ptr control block of one entry.
  static constexpr std::size_t kEntryOverheadBytes = 128;
  // Evicted buffers kept for reuse by later reads.
  static constexpr std::size_t kMaxSpareBuffers = 8;

  // `source` may be null for a cache filled only by Insert(); Get() then
  // throws InvalidArgument on a miss.
  BlockCache(const BlockSource* source, std::size_t capacity_bytes);
  BlockCache(const BlockCache&) = delete;
  BlockCache& operator=(const BlockCache&) = delete;
  ~BlockCache();

  // Returns the block pinned: from memory on a hit, otherwise read through the
  // source on this thread (or by waiting for a read of the same block already
  // in flight on another thread). Blocks for the read. A source error is
  // thrown to the reader and to every waiter (each its own copy of the same
  // Error: kind and message) and nothing is cached for the block; a later
  // Get() tries again.
  PinnedBlock Get(const BlockId& id) EXCLUDES(mutex_);

  // Reads those of `ids` that are neither resident nor being read with one
  // BlockSource::ReadBlocks call (from a server: blocks near one another in
  // one request) and caches them unpinned; returns, for each of `ids`,
  // whether this call read it. A Get() of one of them meanwhile waits for
  // this read. When the read fails, nothing of it is cached, its error is
  // thrown to the caller, and those waiting Get() calls read their blocks
  // themselves: the failure may be another block's.
  std::vector<bool> Load(std::span<const BlockId> ids) EXCLUDES(mutex_);

  // Non-blocking: returns the block pinned if it is resident, else an empty
  // handle (also while a read of it is still in flight).
  PinnedBlock TryGet(const BlockId& id) EXCLUDES(mutex_);

  // If the block is resident, marks it most recently used and returns true.
  // Not counted as a lookup (the prefetcher uses it to skip resident blocks
  // and keeps its own count).
  bool Touch(const BlockId& id) EXCLUDES(mutex_);

  // True if the block is resident. No effect on recency or statistics.
  bool Contains(const BlockId& id) const EXCLUDES(mutex_);

  // Adds (or replaces) a block and returns it pinned; drop the handle to leave
  // it merely cached. A replaced entry that is still pinned stays valid for
  // its holders but is no longer findable.
  PinnedBlock Insert(const BlockId& id, Bytes bytes) EXCLUDES(mutex_);

  // Removes the block if resident; returns whether it was. Pinned holders keep
  // valid bytes. A read of the block already in flight is not cancelled and
  // will insert its result when it completes.
  bool Erase(const BlockId& id) EXCLUDES(mutex_);

  // Erase() of every resident block.
  void Clear() EXCLUDES(mutex_);

  std::size_t capacity_bytes() const { return capacity_bytes_; }
  CacheStats Stats() const EXCLUDES(mutex_);

  // The charge of a block of `size` bytes against the budget.
  static constexpr std::size_t ChargeFor(std::size_t size) { return size + kEntryOverheadBytes; }

 private:
  friend class PinnedBlock;
  enum class Where { kLru, kInUse, kDetached };
  struct Entry {
    BlockId id;
    std::list<Entry>::iterator self;  // this entry's position; splice keeps it valid
    std::shared_ptr<const Bytes> bytes;
    std::size_t charge = 0;
    std::uint32_t pins = 0;
    Where where = Where::kLru;
  };
  using EntryList = std::list<Entry>;
  // A read in progress; waiters sleep on `done_cv` until `done`.
  struct Flight {
    bool done = false;
    // The failure, if the read failed: an Error is kept by value and thrown
    // afresh to each waiter (see ThreadOwnCopy in the .cc); anything else
    // (e.g. bad_alloc) is kept as thrown.
    std::optional<Error> error;
    std::exception_ptr other_error;
    // The reader's read was cancelled (storage/read_cancellation.h): its
    // waiters, who did not cancel, read the block themselves.
    bool cancelled = false;
    std::size_t waiters = 0;           // Get() calls sleeping on this flight
    Entry* entry = nullptr;             // set once done without error
    CondVar done_cv;
  };

  Entry* FindLocked(const BlockId& id) REQUIRES(mutex_);
  PinnedBlock PinLocked(Entry* entry) REQUIRES(mutex_);
  Entry* InsertPinnedLocked(const BlockId& id, std::shared_ptr<const Bytes> bytes, std::uint32_t pins)
      REQUIRES(mutex_);
  void RemoveFromCacheLocked(Entry* entry) REQUIRES(mutex_);
  void UnchargeLocked(Entry* entry) REQUIRES(mutex_);
  void EvictLocked() REQUIRES(mutex_);
  // Called by PinnedBlock::Release().
  void Unpin(Entry* entry) EXCLUDES(mutex_);

  friend class Prefetcher;  // asks the source whether and where to coalesce reads
  const BlockSource* source() const { return source_; }

  const BlockSource* const source_;
  const std::size_t capacity_bytes_;

  // Guards the lists, the table, the flights and the entries and flights
  // they hold.
  mutable Mutex mutex_;
  EntryList lru_ GUARDED_BY(mutex_);                     // unpinned, least recent first
  std::vector<Bytes> spare_buffers_ GUARDED_BY(mutex_);  // evicted buffers for reuse
  EntryList in_use_ GUARDED_BY(mutex_);                  // pinned
  EntryList detached_ GUARDED_BY(mutex_);                // pinned but erased
  using Table = std::unordered_map<BlockId, Entry*, BlockIdHash>;
  Table table_ GUARDED_BY(mutex_);
  std::unordered_map<BlockId, std::shared_ptr<Flight>, BlockIdHash> flights_ GUARDED_BY(mutex_);
  CacheStats stats_ GUARDED_BY(mutex_);  // counters and gauges kept up to date in place
};

// A pinned reference to one cached block. While any handle to a block is
// alive the block is not evicted. Move-only; an empty (default or moved-from)
// handle is false. Handles may be released on any thread, but one handle must
// not be used by two threads at once.
class PinnedBlock {
 public:
  PinnedBlock() = default;
  PinnedBlock(PinnedBlock&& other) noexcept;
  PinnedBlock& operator=(PinnedBlock&& other) noexcept;
  PinnedBlock(const PinnedBlock&) = delete;
  PinnedBlock& operator=(const PinnedBlock&) = delete;
  ~PinnedBlock();

  explicit operator bool() const { return cache_ != nullptr; }
  // Precondition for the accessors below: the handle is not empty.
  const BlockId& id() const;
  const Bytes& bytes() const { return *bytes_; }
  const std::uint8_t* data() const { return bytes_->data(); }
  std::size_t size() const { return bytes_->size(); }
  // Shared ownership of the bytes that outlives the pin (and the cache); it
  // does not keep the block from being evicted.
  std::shared_ptr<const Bytes> Share() const { return bytes_; }

  // Unpins now (the handle becomes empty). Idempotent.
  void Release();

 private:
  friend class BlockCache;
  PinnedBlock(BlockCache* cache, BlockCache::Entry* entry);

  BlockCache* cache_ = nullptr;
  BlockCache::Entry* entry_ = nullptr;  // counted in entry_->pins
  std::shared_ptr<const Bytes> bytes_;
};

}  // namespace octocosm
