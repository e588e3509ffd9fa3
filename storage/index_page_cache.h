// A bounded, thread-safe LRU cache of decoded index pages, keyed by page
// number, plus one pinned slot for the root (every look-up starts there, so
// it must never be evicted by a scan).
//
// Pages are shared_ptr<const IndexPage>: a reader keeps using a page it got
// even after the cache evicted it. Decoding happens outside the lock; two
// threads missing the same page may both read it, which costs one extra
// read and is simpler than making the second wait.
#pragma once

#include <cstdint>
#include <list>
#include <memory>
#include <unordered_map>

#include "base/mutex.h"
#include "storage/block_index_format.h"

namespace octocosm {

class IndexPageCache {
 public:
  explicit IndexPageCache(std::size_t capacity_pages);

  std::shared_ptr<const IndexPage> Find(std::uint64_t page_number) EXCLUDES(mutex_);
  void Insert(std::shared_ptr<const IndexPage> page) EXCLUDES(mutex_);

  std::shared_ptr<const IndexPage> root() EXCLUDES(mutex_);
  void SetRoot(std::shared_ptr<const IndexPage> page) EXCLUDES(mutex_);

  // Drops every page but the root.
  void Clear() EXCLUDES(mutex_);
  std::size_t size() EXCLUDES(mutex_);

 private:
  struct Slot {
    std::shared_ptr<const IndexPage> page;
    std::list<std::uint64_t>::iterator position;  // in recency_
  };

  const std::size_t capacity_;
  Mutex mutex_;
  std::shared_ptr<const IndexPage> root_ GUARDED_BY(mutex_);
  std::list<std::uint64_t> recency_ GUARDED_BY(mutex_);  // most recent first
  std::unordered_map<std::uint64_t, Slot> pages_ GUARDED_BY(mutex_);
};

}  // namespace octocosm
