#include "storage/index_page_cache.h"

#include <algorithm>

namespace octocosm {

IndexPageCache::IndexPageCache(std::size_t capacity_pages) : capacity_(std::max<std::size_t>(1, capacity_pages)) {}

std::shared_ptr<const IndexPage> IndexPageCache::Find(std::uint64_t page_number) {
  MutexLock lock(mutex_);
  if (root_ && root_->page_number == page_number) return root_;
  auto found = pages_.find(page_number);
  if (found == pages_.end()) return nullptr;
  recency_.splice(recency_.begin(), recency_, found->second.position);
  return found->second.page;
}

void IndexPageCache::Insert(std::shared_ptr<const IndexPage> page) {
  MutexLock lock(mutex_);
  const std::uint64_t number = page->page_number;
  if (pages_.contains(number)) return;  // another thread read it first
  recency_.push_front(number);
  pages_.emplace(number, Slot{std::move(page), recency_.begin()});
  while (pages_.size() > capacity_) {
    pages_.erase(recency_.back());
    recency_.pop_back();
  }
}

std::shared_ptr<const IndexPage> IndexPageCache::root() {
  MutexLock lock(mutex_);
  return root_;
}

void IndexPageCache::SetRoot(std::shared_ptr<const IndexPage> page) {
  MutexLock lock(mutex_);
  if (!root_) root_ = std::move(page);
}

void IndexPageCache::Clear() {
  MutexLock lock(mutex_);
  pages_.clear();
  recency_.clear();
}

std::size_t IndexPageCache::size() {
  MutexLock lock(mutex_);
  return pages_.size() + (root_ ? 1 : 0);
}

}  // namespace octocosm
