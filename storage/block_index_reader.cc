#include "storage/block_index_reader.h"

#include <algorithm>

#include "base/error.h"
#include "storage/checksum.h"

namespace octocosm {

BlockIndexReader::BlockIndexReader(std::string path, std::uint32_t epoch, std::uint32_t page_size,
                                   const IndexLayout& layout, PageReader read_page, Options options)
    : path_(std::move(path)),
      epoch_(epoch),
      page_size_(page_size),
      layout_(layout),
      read_page_(std::move(read_page)),
      cache_(options.cache_pages) {
  std::uint64_t first = layout_.first_page;
  // The header decoder has checked that the layout matches this shape.
  interior_capacity_ = InteriorCapacity(page_size);
  std::uint64_t pages = layout_.leaf_page_count;
  for (std::uint32_t level = 0; level < layout_.height; ++level) {
    level_first_page_.push_back(first);
    level_page_count_.push_back(pages);
    first += pages;
    pages = (pages + interior_capacity_ - 1) / interior_capacity_;
  }
}

Error BlockIndexReader::TreeCorruption(std::uint64_t page_number, const std::string& what) const {
  return Error::Corruption(path_, "index page " + std::to_string(page_number) + " (epoch " +
                                      std::to_string(epoch_) + "): " + what);
}

std::shared_ptr<const IndexPage> BlockIndexReader::LoadPage(std::uint64_t page_number, std::uint8_t level) const {
  if (auto cached = cache_.Find(page_number)) {
    cache_hits_.fetch_add(1, std::memory_order_relaxed);
    return cached;
  }
  std::vector<std::uint8_t> bytes(page_size_);
  read_page_(page_number, bytes);
  page_reads_.fetch_add(1, std::memory_order_relaxed);
  IndexPageExpectation expect{path_, epoch_, page_size_, page_number, level, layout_};
  auto page = std::make_shared<const IndexPage>(DecodeIndexPage(bytes, expect));
  if (page_number != layout_.root_page) cache_.Insert(page);
  return page;
}

std::shared_ptr<const IndexPage> BlockIndexReader::LoadRoot() const {
  if (auto root = cache_.root()) {
    cache_hits_.fetch_add(1, std::memory_order_relaxed);
    return root;
  }
  auto root = LoadPage(layout_.root_page, static_cast<std::uint8_t>(layout_.height - 1));
  cache_.SetRoot(root);
  return root;
}

std::shared_ptr<const IndexPage> BlockIndexReader::FindLeaf(std::uint64_t key) const {
  std::shared_ptr<const IndexPage> page = LoadRoot();
  while (!page->is_leaf()) {
    const auto& entries = page->interior_entries;
    auto after = std::upper_bound(entries.begin(), entries.end(), key,
                                  [](std::uint64_t k, const InteriorEntry& e) { return k < e.first_key; });
    std::size_t index = after == entries.begin() ? 0 : static_cast<std::size_t>(after - entries.begin()) - 1;
    const InteriorEntry& link = entries[index];
    const auto child_level = static_cast<std::uint8_t>(page->level - 1);
    // The shape fixes which pages a page links and how many: a page that
    // links fewer would hide the others' blocks from look-ups, which a scan,
    // going leaf by leaf, still finds.
    const std::uint64_t first_child = (page->page_number - level_first_page_[page->level]) * interior_capacity_;
    const std::uint64_t children = level_page_count_[child_level];
    const std::uint64_t expected_count =
        first_child < children ? std::min(interior_capacity_, children - first_child) : 0;
    if (entries.size() != expected_count) {
      throw TreeCorruption(page->page_number, "links " + std::to_string(entries.size()) +
                                                  " pages; the index's shape says " + std::to_string(expected_count));
    }
    const std::uint64_t expected_child = level_first_page_[child_level] + first_child + index;
    if (link.child_page != expected_child) {
      throw TreeCorruption(page->page_number, "entry " + std::to_string(index) + " links page " +
                                                  std::to_string(link.child_page) + "; the index's shape says " +
                                                  std::to_string(expected_child));
    }
    std::shared_ptr<const IndexPage> child = LoadPage(link.child_page, child_level);
    // The separator must be the child's first key, and the child must end
    // before the next separator; otherwise keys would be found in the wrong
    // subtree or not at all.
    if (child->first_key() != link.first_key ||
        (index + 1 < entries.size() && child->last_key() >= entries[index + 1].first_key)) {
      throw TreeCorruption(page->page_number, "child page " + std::to_string(link.child_page) +
                                                  " holds keys outside its separator " + Hex64(link.first_key));
    }
    // A key between this child's last and the next separator is in no page,
    // unless the next separator is wrong: then it would lie in the next child.
    if (key > child->last_key() && index + 1 < entries.size()) {
      const InteriorEntry& next = entries[index + 1];
      if (next.child_page != expected_child + 1 ||
          LoadPage(next.child_page, child_level)->first_key() != next.first_key) {
        throw TreeCorruption(page->page_number, "child page " + std::to_string(next.child_page) +
                                                    " does not begin at its separator " + Hex64(next.first_key));
      }
    }
    page = std::move(child);
  }
  return page;
}

std::optional<IndexEntry> BlockIndexReader::Lookup(std::uint64_t key) const {
  if (layout_.height == 0) return std::nullopt;
  std::shared_ptr<const IndexPage> leaf = FindLeaf(key);
  const auto& entries = leaf->leaf_entries;
  auto found = std::lower_bound(entries.begin(), entries.end(), key,
                                [](const IndexEntry& e, std::uint64_t k) { return e.key < k; });
  if (found == entries.end() || found->key != key) return std::nullopt;
  return *found;
}

void BlockIndexReader::Scan(std::uint64_t lo, std::uint64_t hi,
                            const std::function<bool(const IndexEntry&)>& visit) const {
  if (layout_.height == 0 || lo > hi) return;
  std::shared_ptr<const IndexPage> leaf = FindLeaf(lo);
  const std::uint64_t leaves_end = layout_.first_page + layout_.leaf_page_count;
  while (true) {
    for (const IndexEntry& entry : leaf->leaf_entries) {
      if (entry.key < lo) continue;
      if (entry.key > hi) return;
      if (!visit(entry)) return;
    }
    const std::uint64_t next = leaf->page_number + 1;
    if (next >= leaves_end) return;
    std::shared_ptr<const IndexPage> next_leaf = LoadPage(next, 0);
    if (next_leaf->first_key() <= leaf->last_key()) {
      throw TreeCorruption(next, "leaf keys out of order: first key " + Hex64(next_leaf->first_key()) +
                                     " is not above the previous leaf's last key " + Hex64(leaf->last_key()));
    }
    // A scan goes leaf by leaf, a look-up down the tree: both must find the
    // same blocks (the pages of the way down are cached).
    if (FindLeaf(next_leaf->first_key())->page_number != next) {
      throw TreeCorruption(next, "the tree leads its first key " + Hex64(next_leaf->first_key()) +
                                     " to another leaf");
    }
    leaf = std::move(next_leaf);
  }
}

}  // namespace octocosm
