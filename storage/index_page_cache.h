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
#include <mutex>
#include <unordered_map>

#include "storage/block_index_format.h"

namespace octocosm {

class IndexPageCache {
 public:
  explicit IndexPageCache(std::size_t capacity_pages);

  std::shared_ptr<const IndexPage> Find(std::uint64_t page_number);
  void Insert(std::shared_ptr<const IndexPage> page);

  std::shared_ptr<const IndexPage> root();
  void SetRoot(std::shared_ptr<const IndexPage> page);

  // Drops every page but the root.
  void Clear();
  std::size_t size();

 private:
  struct Slot {
    std::shared_ptr<const IndexPage> page;
    std::list<std::uint64_t>::iterator position;  // in recency_
  };

  const std::size_t capacity_;
  std::mutex mutex_;
  std::shared_ptr<const IndexPage> root_;             // guarded by mutex_
  std::list<std::uint64_t> recency_;                  // most recent first; guarded by mutex_
  std::unordered_map<std::uint64_t, Slot> pages_;     // guarded by mutex_
};

}  // namespace octocosm
