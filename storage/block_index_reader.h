// Look-ups and ordered scans over a page file's static B+-tree index
// (docs/FORMAT.md 2.5), reading index pages on demand through a bounded cache.
//
// Nothing is read at construction: a store of 10^7 blocks opens by reading
// its header only. A look-up reads at most `height` pages (fewer when they are
// cached; the root, once read, stays). Every page is checked as it is read,
// and the tree's shape is checked as it is walked (levels, separator keys,
// key order across leaves), so a corrupted index yields kCorruption, never a
// wrong block. Safe for concurrent use.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "base/error.h"
#include "storage/block_index_format.h"
#include "storage/index_page_cache.h"

namespace octocosm {

class BlockIndexReader {
 public:
  // Reads index page `page_number` whole into `out` (page_size bytes); throws
  // kIo, or kCorruption if the file ends first.
  using PageReader = std::function<void(std::uint64_t page_number, std::span<std::uint8_t> out)>;

  struct Options {
    // Decoded pages kept besides the root. A 64 KiB leaf decodes to ~65 KB.
    std::size_t cache_pages = 64;
  };

  // `path` and `epoch` name the file in error messages. `layout` must come
  // from a checked PageFileHeader.
  BlockIndexReader(std::string path, std::uint32_t epoch, std::uint32_t page_size, const IndexLayout& layout,
                   PageReader read_page, Options options);

  std::optional<IndexEntry> Lookup(std::uint64_t key) const;

  // Calls `visit` with every entry whose key is in [lo, hi], in key order,
  // until it returns false.
  void Scan(std::uint64_t lo, std::uint64_t hi, const std::function<bool(const IndexEntry&)>& visit) const;

  // Index pages read from the file so far (cache misses), and cache hits.
  std::uint64_t page_reads() const { return page_reads_.load(std::memory_order_relaxed); }
  std::uint64_t cache_hits() const { return cache_hits_.load(std::memory_order_relaxed); }
  std::uint32_t height() const { return layout_.height; }

  // Forgets cached pages except the root.
  void ClearCache() const { cache_.Clear(); }

 private:
  std::shared_ptr<const IndexPage> LoadPage(std::uint64_t page_number, std::uint8_t level) const;
  std::shared_ptr<const IndexPage> LoadRoot() const;
  // Descends from the root to the leaf that would hold `key` (the first leaf
  // if `key` precedes every key).
  std::shared_ptr<const IndexPage> FindLeaf(std::uint64_t key) const;
  Error TreeCorruption(std::uint64_t page_number, const std::string& what) const;

  const std::string path_;
  const std::uint32_t epoch_;
  const std::uint32_t page_size_;
  const IndexLayout layout_;
  // The tree's shape, from the bulk-load rule: each level's first page and
  // page count (leaves first); a level's pages are filled in order,
  // interior_capacity_ children to a page, the last page with the rest.
  std::uint64_t interior_capacity_ = 0;
  std::vector<std::uint64_t> level_first_page_;
  std::vector<std::uint64_t> level_page_count_;
  const PageReader read_page_;
  mutable IndexPageCache cache_;
  mutable std::atomic<std::uint64_t> page_reads_{0};
  mutable std::atomic<std::uint64_t> cache_hits_{0};
};

}  // namespace octocosm
