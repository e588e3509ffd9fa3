#include "storage/block_cache.h"

#include <cassert>
#include <sstream>
#include <utility>

#include "base/error.h"
#include "storage/read_cancellation.h"

namespace octocosm {

namespace {

// Shared bytes whose object is not itself const, so that an evicted buffer
// nobody else holds may be taken back for reuse (UnchargeLocked).
std::shared_ptr<const Bytes> MakeShared(Bytes bytes) { return std::make_shared<Bytes>(std::move(bytes)); }

// A copy of `error` that shares nothing with it. Copies of a std::runtime_error
// share one message buffer through a reference count inside libstdc++, which
// ThreadSanitizer cannot see; handing each thread its own buffer keeps the
// cache clean under TSan at the cost of one string copy per failed waiter.
Error ThreadOwnCopy(const Error& error) { return Error(error.kind(), error.what()); }

}  // namespace

std::string CacheStats::ToString() const {
  std::ostringstream out;
  out << "cache: " << resident_bytes << "/" << capacity_bytes << " B in " << entries
      << " blocks (pinned " << pinned_bytes << " B in " << pinned_entries << "), hits " << hits
      << ", misses " << misses << ", reads " << source_reads << " (" << bytes_read << " B, "
      << read_failures << " failed, " << reads_in_flight << " in flight), inserts " << inserts
      << ", evictions " << evictions;
  return out.str();
}

// ---------------------------------------------------------------------------
// PinnedBlock

PinnedBlock::PinnedBlock(BlockCache* cache, BlockCache::Entry* entry)
    : cache_(cache), entry_(entry), bytes_(entry->bytes) {}

PinnedBlock::PinnedBlock(PinnedBlock&& other) noexcept
    : cache_(std::exchange(other.cache_, nullptr)),
      entry_(std::exchange(other.entry_, nullptr)),
      bytes_(std::move(other.bytes_)) {}

PinnedBlock& PinnedBlock::operator=(PinnedBlock&& other) noexcept {
  if (this != &other) {
    Release();
    cache_ = std::exchange(other.cache_, nullptr);
    entry_ = std::exchange(other.entry_, nullptr);
    bytes_ = std::move(other.bytes_);
  }
  return *this;
}

PinnedBlock::~PinnedBlock() { Release(); }

const BlockId& PinnedBlock::id() const {
  // The id of an entry never changes after it is created, so no lock.
  return entry_->id;
}

void PinnedBlock::Release() {
  if (cache_ == nullptr) return;
  BlockCache* cache = std::exchange(cache_, nullptr);
  BlockCache::Entry* entry = std::exchange(entry_, nullptr);
  bytes_.reset();
  cache->Unpin(entry);
}

// ---------------------------------------------------------------------------
// BlockCache

BlockCache::BlockCache(const BlockSource* source, std::size_t capacity_bytes)
    : source_(source), capacity_bytes_(capacity_bytes) {
  stats_.capacity_bytes = capacity_bytes;
}

BlockCache::~BlockCache() {
  // A live handle here would later unpin into freed memory.
  assert(in_use_.empty() && detached_.empty() && "a PinnedBlock outlived its BlockCache");
  assert(flights_.empty() && "a Get() is still running on a destroyed BlockCache");
}

BlockCache::Entry* BlockCache::FindLocked(const BlockId& id) {
  auto it = table_.find(id);
  return it == table_.end() ? nullptr : it->second;
}

PinnedBlock BlockCache::PinLocked(Entry* entry) {
  if (entry->pins++ == 0 && entry->where == Where::kLru) {
    in_use_.splice(in_use_.end(), lru_, entry->self);
    entry->where = Where::kInUse;
    stats_.pinned_bytes += entry->charge;
    ++stats_.pinned_entries;
  }
  return PinnedBlock(this, entry);
}

// Makes a new entry findable with `pins` handles already counted for it
// (pins >= 1, so the new entry itself is never the one evicted), replacing any
// entry of the same id, then evicts down to the budget. Both allocations come
// before any change, so a bad_alloc leaves the cache as it was.
BlockCache::Entry* BlockCache::InsertPinnedLocked(const BlockId& id,
                                                  std::shared_ptr<const Bytes> bytes,
                                                  std::uint32_t pins) {
  assert(pins > 0);
  const std::size_t charge = ChargeFor(bytes->size());
  auto position =
      in_use_.insert(in_use_.end(), Entry{id, {}, std::move(bytes), charge, pins, Where::kInUse});
  position->self = position;
  Entry* entry = &*position;
  std::pair<Table::iterator, bool> slot;
  try {
    slot = table_.try_emplace(id, entry);
  } catch (...) {
    in_use_.erase(position);
    throw;
  }
  if (!slot.second) {
    UnchargeLocked(slot.first->second);
    slot.first->second = entry;
  }
  stats_.resident_bytes += charge;
  stats_.pinned_bytes += charge;
  ++stats_.entries;
  ++stats_.pinned_entries;
  ++stats_.inserts;
  EvictLocked();
  return entry;
}

void BlockCache::RemoveFromCacheLocked(Entry* entry) {
  table_.erase(entry->id);
  UnchargeLocked(entry);
}

// Takes an entry whose table slot is gone or reused off the budget: freed now
// if unpinned, otherwise moved to detached_ until its last handle goes.
void BlockCache::UnchargeLocked(Entry* entry) {
  stats_.resident_bytes -= entry->charge;
  --stats_.entries;
  if (entry->where == Where::kLru) {
    // Nobody else holds the bytes (no handle, no Share()): keep the buffer.
    // It was created non-const (see MakeShared), so taking it back is sound.
    if (entry->bytes.use_count() == 1 && spare_buffers_.size() < kMaxSpareBuffers) {
      spare_buffers_.push_back(std::move(const_cast<Bytes&>(*entry->bytes)));
    }
    lru_.erase(entry->self);
  } else {
    assert(entry->where == Where::kInUse);
    stats_.pinned_bytes -= entry->charge;
    --stats_.pinned_entries;
    detached_.splice(detached_.end(), in_use_, entry->self);
    entry->where = Where::kDetached;
  }
}

void BlockCache::EvictLocked() {
  while (stats_.resident_bytes > capacity_bytes_ && !lru_.empty()) {
    RemoveFromCacheLocked(&lru_.front());
    ++stats_.evictions;
  }
}

void BlockCache::Unpin(Entry* entry) {
  MutexLock lock(mutex_);
  assert(entry->pins > 0);
  if (--entry->pins > 0) return;
  switch (entry->where) {
    case Where::kInUse:
      lru_.splice(lru_.end(), in_use_, entry->self);
      entry->where = Where::kLru;
      stats_.pinned_bytes -= entry->charge;
      --stats_.pinned_entries;
      EvictLocked();
      break;
    case Where::kDetached:
      detached_.erase(entry->self);
      break;
    case Where::kLru:
      assert(false && "an unpinned entry was on the in-use side");
      break;
  }
}

PinnedBlock BlockCache::Get(const BlockId& id) {
  std::shared_ptr<Flight> flight;
  Bytes buffer;  // a recycled one when there is one
  {
    MutexLock lock(mutex_);
    if (Entry* entry = FindLocked(id)) {
      ++stats_.hits;
      return PinLocked(entry);
    }
    ++stats_.misses;
    // Someone else is reading this block: wait for their result rather than
    // read it twice. The reader pins the new entry once for every waiter. A
    // read its reader cancelled leaves the block to the next caller.
    for (auto running = flights_.find(id); running != flights_.end(); running = flights_.find(id)) {
      std::shared_ptr<Flight> joined = running->second;
      ++joined->waiters;
      while (!joined->done) joined->done_cv.Wait(mutex_);
      if (joined->cancelled) {
        if (Entry* entry = FindLocked(id)) return PinLocked(entry);
        continue;
      }
      if (joined->error) throw ThreadOwnCopy(*joined->error);
      if (joined->other_error) std::rethrow_exception(joined->other_error);
      return PinnedBlock(this, joined->entry);
    }
    if (source_ == nullptr) {
      throw Error::InvalidArgument("block cache has no source to read a missing block from");
    }
    flight = std::make_shared<Flight>();
    flights_.emplace(id, flight);
    if (!spare_buffers_.empty()) {
      buffer = std::move(spare_buffers_.back());
      spare_buffers_.pop_back();
    }
    ++stats_.source_reads;
    ++stats_.reads_in_flight;
  }

  std::shared_ptr<const Bytes> bytes;
  std::exception_ptr thrown;  // this thread's own exception, rethrown to this caller
  std::optional<Error> error_for_waiters;
  try {
    source_->ReadBlock(id, buffer);
    bytes = MakeShared(std::move(buffer));
  } catch (const Error& e) {
    thrown = std::current_exception();
    error_for_waiters = ThreadOwnCopy(e);
  } catch (...) {
    thrown = std::current_exception();
  }

  MutexLock lock(mutex_);
  flights_.erase(id);
  --stats_.reads_in_flight;
  flight->done = true;
  if (thrown) {
    flight->cancelled = ReadCancelled();
    if (!flight->cancelled) ++stats_.read_failures;
    if (error_for_waiters) {
      flight->error = std::move(error_for_waiters);
    } else {
      flight->other_error = thrown;
    }
    flight->done_cv.SignalAll();
    std::rethrow_exception(thrown);
  }
  stats_.bytes_read += bytes->size();
  const auto pins = static_cast<std::uint32_t>(1 + flight->waiters);
  try {
    flight->entry = InsertPinnedLocked(id, std::move(bytes), pins);
  } catch (...) {
    flight->other_error = std::current_exception();
    flight->done_cv.SignalAll();
    throw;
  }
  flight->done_cv.SignalAll();
  return PinnedBlock(this, flight->entry);
}

std::vector<bool> BlockCache::Load(std::span<const BlockId> ids) {
  std::vector<bool> read(ids.size(), false);
  std::vector<BlockId> reading;
  std::vector<std::shared_ptr<Flight>> flights;
  std::vector<Bytes> buffers;
  {
    MutexLock lock(mutex_);
    if (source_ == nullptr) {
      throw Error::InvalidArgument("block cache has no source to read missing blocks from");
    }
    for (std::size_t i = 0; i < ids.size(); ++i) {
      if (FindLocked(ids[i]) != nullptr || flights_.contains(ids[i])) continue;
      auto flight = std::make_shared<Flight>();
      flights_.emplace(ids[i], flight);
      reading.push_back(ids[i]);
      flights.push_back(std::move(flight));
      buffers.emplace_back();
      if (!spare_buffers_.empty()) {
        buffers.back() = std::move(spare_buffers_.back());
        spare_buffers_.pop_back();
      }
      read[i] = true;
      ++stats_.source_reads;
      ++stats_.reads_in_flight;
    }
  }
  if (reading.empty()) return read;

  std::exception_ptr thrown;
  try {
    source_->ReadBlocks(reading, buffers);
  } catch (...) {
    thrown = std::current_exception();
  }

  // Handles that keep each new entry pinned until the lock is released, so
  // that inserting one cannot evict another before its waiters have it.
  std::vector<PinnedBlock> inserted;
  inserted.reserve(reading.size());
  MutexLock lock(mutex_);
  for (std::size_t i = 0; i < reading.size(); ++i) {
    Flight& flight = *flights[i];
    flights_.erase(reading[i]);
    --stats_.reads_in_flight;
    flight.done = true;
    if (thrown) {
      // Waiters read their blocks themselves, as after a cancelled read.
      flight.cancelled = true;
    } else {
      try {
        stats_.bytes_read += buffers[i].size();
        flight.entry = InsertPinnedLocked(reading[i], MakeShared(std::move(buffers[i])),
                                          static_cast<std::uint32_t>(1 + flight.waiters));
        inserted.push_back(PinnedBlock(this, flight.entry));
      } catch (...) {
        flight.other_error = std::current_exception();
      }
    }
    flight.done_cv.SignalAll();
  }
  if (thrown) {
    if (!ReadCancelled()) stats_.read_failures += reading.size();
    lock.Unlock();
    std::rethrow_exception(thrown);
  }
  lock.Unlock();
  return read;
}

PinnedBlock BlockCache::TryGet(const BlockId& id) {
  MutexLock lock(mutex_);
  Entry* entry = FindLocked(id);
  if (entry == nullptr) {
    ++stats_.misses;
    return {};
  }
  ++stats_.hits;
  return PinLocked(entry);
}

bool BlockCache::Touch(const BlockId& id) {
  MutexLock lock(mutex_);
  Entry* entry = FindLocked(id);
  if (entry == nullptr) return false;
  if (entry->where == Where::kLru) lru_.splice(lru_.end(), lru_, entry->self);
  return true;
}

bool BlockCache::Contains(const BlockId& id) const {
  MutexLock lock(mutex_);
  return table_.contains(id);
}

PinnedBlock BlockCache::Insert(const BlockId& id, Bytes bytes) {
  auto shared = MakeShared(std::move(bytes));
  MutexLock lock(mutex_);
  return PinnedBlock(this, InsertPinnedLocked(id, std::move(shared), 1));
}

bool BlockCache::Erase(const BlockId& id) {
  MutexLock lock(mutex_);
  Entry* entry = FindLocked(id);
  if (entry == nullptr) return false;
  RemoveFromCacheLocked(entry);
  return true;
}

void BlockCache::Clear() {
  MutexLock lock(mutex_);
  while (!table_.empty()) RemoveFromCacheLocked(table_.begin()->second);
}

CacheStats BlockCache::Stats() const {
  MutexLock lock(mutex_);
  return stats_;
}

}  // namespace octocosm
