// Bulk loading of the static B+-tree index (docs/FORMAT.md 2.5).
//
// The index is built once, when a page file is finished, from all of its
// entries: leaves are packed full in key order, then each interior level is
// built from the first keys of the level below, up to a single root. A static
// tree needs no free space or splits, so pages are full and a look-up reads
// exactly `height` pages.
#pragma once

#include <cstdint>
#include <functional>
#include <span>

#include "storage/block_index_format.h"

namespace octocosm {

// Receives each encoded index page in increasing page-number order.
using IndexPageSink = std::function<void(std::uint64_t page_number, std::span<const std::uint8_t> page)>;

// Writes `sorted_entries` (strictly increasing keys; the caller checks) as
// index pages numbered from `first_page`, passing each to `sink`. Returns
// where the tree went, for the page-file header. No pages for no entries.
// Memory: one page plus 16 bytes per leaf, so 10^7 entries need ~120 KB
// beyond the entries themselves.
IndexLayout BuildBlockIndex(std::span<const IndexEntry> sorted_entries, std::uint64_t first_page,
                            std::uint32_t page_size, const IndexPageSink& sink);

}  // namespace octocosm
