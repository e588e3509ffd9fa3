// Index pages of the static B+-tree (docs/FORMAT.md section 2.5): their
// header, the leaf and interior entries, the bulk-load shape, and a checking
// decoder. The tree logic (look-up, scan, bulk load) lives in block_index.h.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "storage/page_file_format.h"

namespace octocosm {

inline constexpr std::array<std::uint8_t, 4> kIndexPageMagic = {'O', 'C', 'I', 'X'};
inline constexpr std::size_t kIndexPageHeaderSize = 32;
inline constexpr std::size_t kLeafEntrySize = 48;
inline constexpr std::size_t kInteriorEntrySize = 16;
inline constexpr std::uint8_t kLeafPageKind = 1;
inline constexpr std::uint8_t kInteriorPageKind = 2;
// More levels than any page size and 2^64 keys could need; a header claiming
// more is corrupt.
inline constexpr std::uint32_t kMaxIndexHeight = 32;

// Where a block is and how to check it: one leaf entry.
struct IndexEntry {
  std::uint64_t key = 0;
  std::uint64_t first_page = 0;
  std::uint64_t byte_length = 0;
  std::uint64_t point_count = 0;
  std::uint64_t checksum = 0;
  std::uint32_t page_count = 0;

  friend bool operator==(const IndexEntry&, const IndexEntry&) = default;
};

struct InteriorEntry {
  std::uint64_t first_key = 0;
  std::uint64_t child_page = 0;
};

std::size_t LeafCapacity(std::uint32_t page_size);
std::size_t InteriorCapacity(std::uint32_t page_size);

// Pages needed for a block of `byte_length` bytes; nullopt if the count does
// not fit the on-disk u32.
std::optional<std::uint32_t> PagesForBytes(std::uint64_t byte_length, std::uint32_t page_size);

// The shape the bulk-load rule gives `block_count` entries: number of pages
// per level (leaves first) and, from it, the totals recorded in the header.
struct IndexShape {
  std::vector<std::uint64_t> pages_per_level;
  std::uint64_t total_pages() const;
  std::uint64_t leaf_pages() const { return pages_per_level.empty() ? 0 : pages_per_level[0]; }
  std::uint32_t height() const { return static_cast<std::uint32_t>(pages_per_level.size()); }
};
IndexShape ComputeIndexShape(std::uint64_t block_count, std::uint32_t page_size);

// One decoded index page: either leaf entries or interior entries.
struct IndexPage {
  std::uint64_t page_number = 0;
  std::uint8_t level = 0;
  std::vector<IndexEntry> leaf_entries;         // level 0
  std::vector<InteriorEntry> interior_entries;  // level > 0

  bool is_leaf() const { return level == 0; }
  std::uint64_t first_key() const;
  std::uint64_t last_key() const;
  std::size_t approximate_bytes() const;
};

// Encoders fill a whole page of `page_size` bytes. Entries must be sorted and
// within capacity (the bulk loader guarantees it).
std::vector<std::uint8_t> EncodeLeafPage(std::uint64_t page_number, std::span<const IndexEntry> entries,
                                         std::uint32_t page_size);
std::vector<std::uint8_t> EncodeInteriorPage(std::uint64_t page_number, std::uint8_t level,
                                             std::span<const InteriorEntry> entries, std::uint32_t page_size);

// What a decoder needs to know to check a page: where it came from and what
// it must look like. `file_label` names the file (and epoch) in messages.
struct IndexPageExpectation {
  std::string path;
  std::uint32_t epoch = 0;
  std::uint32_t page_size = 0;
  std::uint64_t page_number = 0;
  std::uint8_t level = 0;
  IndexLayout layout;
};

// Decodes and checks a page (docs/FORMAT.md 2.5 "Every index page is checked
// when read"). Throws kCorruption naming the file, epoch and page.
IndexPage DecodeIndexPage(std::span<const std::uint8_t> page, const IndexPageExpectation& expect);

// Checks one leaf entry against the page geometry; throws kCorruption naming
// the key. Exposed so the writer can never produce what a reader rejects.
void CheckIndexEntry(const IndexEntry& entry, std::uint32_t page_size, std::uint64_t data_end_page,
                     const std::string& path, std::uint32_t epoch);

}  // namespace octocosm
