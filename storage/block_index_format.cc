#include "storage/block_index_format.h"

#include <algorithm>

#include "base/error.h"
#include "storage/checksum.h"
#include "storage/coding.h"

namespace octocosm {
namespace {

namespace page_offset {
constexpr std::size_t kMagic = 0;
constexpr std::size_t kKind = 4;
constexpr std::size_t kLevel = 5;
constexpr std::size_t kReserved16 = 6;
constexpr std::size_t kEntryCount = 8;
constexpr std::size_t kReserved32 = 12;
constexpr std::size_t kPageNumber = 16;
constexpr std::size_t kChecksum = 24;
}  // namespace page_offset

namespace leaf_offset {
constexpr std::size_t kKey = 0;
constexpr std::size_t kFirstPage = 8;
constexpr std::size_t kByteLength = 16;
constexpr std::size_t kPointCount = 24;
constexpr std::size_t kChecksum = 32;
constexpr std::size_t kPageCount = 40;
constexpr std::size_t kReserved = 44;
}  // namespace leaf_offset

// The checksum covers the page header around its own field and the used
// entries, so that padding after the last entry need not be hashed.
std::uint64_t IndexPageChecksum(std::span<const std::uint8_t> page, std::size_t entries_bytes) {
  return Checksum64(page.first(page_offset::kChecksum),
                    page.subspan(kIndexPageHeaderSize, entries_bytes));
}

std::vector<std::uint8_t> EncodePage(std::uint64_t page_number, std::uint8_t kind, std::uint8_t level,
                                     std::size_t count, std::size_t entry_size, std::uint32_t page_size,
                                     const auto& write_entry) {
  std::vector<std::uint8_t> page(page_size, 0);
  std::copy(kIndexPageMagic.begin(), kIndexPageMagic.end(), page.begin());
  page[page_offset::kKind] = kind;
  page[page_offset::kLevel] = level;
  PutU32(&page[page_offset::kEntryCount], static_cast<std::uint32_t>(count));
  PutU64(&page[page_offset::kPageNumber], page_number);
  for (std::size_t i = 0; i < count; ++i) write_entry(&page[kIndexPageHeaderSize + i * entry_size], i);
  PutU64(&page[page_offset::kChecksum], IndexPageChecksum(page, count * entry_size));
  return page;
}

}  // namespace

std::size_t LeafCapacity(std::uint32_t page_size) {
  return (page_size - kIndexPageHeaderSize) / kLeafEntrySize;
}

std::size_t InteriorCapacity(std::uint32_t page_size) {
  return (page_size - kIndexPageHeaderSize) / kInteriorEntrySize;
}

std::optional<std::uint32_t> PagesForBytes(std::uint64_t byte_length, std::uint32_t page_size) {
  std::uint64_t pages = byte_length / page_size + (byte_length % page_size != 0 ? 1 : 0);
  if (pages > UINT32_MAX) return std::nullopt;
  return static_cast<std::uint32_t>(pages);
}

std::uint64_t IndexShape::total_pages() const {
  std::uint64_t total = 0;
  for (std::uint64_t pages : pages_per_level) total += pages;
  return total;
}

IndexShape ComputeIndexShape(std::uint64_t block_count, std::uint32_t page_size) {
  IndexShape shape;
  if (block_count == 0) return shape;
  const std::uint64_t leaf_capacity = LeafCapacity(page_size);
  const std::uint64_t interior_capacity = InteriorCapacity(page_size);
  std::uint64_t pages = (block_count + leaf_capacity - 1) / leaf_capacity;
  shape.pages_per_level.push_back(pages);
  while (pages > 1) {
    pages = (pages + interior_capacity - 1) / interior_capacity;
    shape.pages_per_level.push_back(pages);
  }
  return shape;
}

std::uint64_t IndexPage::first_key() const {
  return is_leaf() ? leaf_entries.front().key : interior_entries.front().first_key;
}

std::uint64_t IndexPage::last_key() const {
  return is_leaf() ? leaf_entries.back().key : interior_entries.back().first_key;
}

std::size_t IndexPage::approximate_bytes() const {
  return sizeof(IndexPage) + leaf_entries.size() * sizeof(IndexEntry) +
         interior_entries.size() * sizeof(InteriorEntry);
}

std::vector<std::uint8_t> EncodeLeafPage(std::uint64_t page_number, std::span<const IndexEntry> entries,
                                         std::uint32_t page_size) {
  return EncodePage(page_number, kLeafPageKind, 0, entries.size(), kLeafEntrySize, page_size,
                    [&](std::uint8_t* out, std::size_t i) {
                      const IndexEntry& entry = entries[i];
                      PutU64(out + leaf_offset::kKey, entry.key);
                      PutU64(out + leaf_offset::kFirstPage, entry.first_page);
                      PutU64(out + leaf_offset::kByteLength, entry.byte_length);
                      PutU64(out + leaf_offset::kPointCount, entry.point_count);
                      PutU64(out + leaf_offset::kChecksum, entry.checksum);
                      PutU32(out + leaf_offset::kPageCount, entry.page_count);
                    });
}

std::vector<std::uint8_t> EncodeInteriorPage(std::uint64_t page_number, std::uint8_t level,
                                             std::span<const InteriorEntry> entries, std::uint32_t page_size) {
  return EncodePage(page_number, kInteriorPageKind, level, entries.size(), kInteriorEntrySize, page_size,
                    [&](std::uint8_t* out, std::size_t i) {
                      PutU64(out, entries[i].first_key);
                      PutU64(out + 8, entries[i].child_page);
                    });
}

void CheckIndexEntry(const IndexEntry& entry, std::uint32_t page_size, std::uint64_t data_end_page,
                     const std::string& path, std::uint32_t epoch) {
  auto bad = [&](const std::string& what) {
    return Error::Corruption(path, "block " + Hex64(entry.key) + " (epoch " + std::to_string(epoch) +
                                       "): bad index entry: " + what);
  };
  std::optional<std::uint32_t> pages = PagesForBytes(entry.byte_length, page_size);
  if (!pages || *pages != entry.page_count) {
    throw bad("page count " + std::to_string(entry.page_count) + " does not fit byte length " +
              std::to_string(entry.byte_length));
  }
  if (entry.page_count == 0) {
    if (entry.first_page != 0) {
      throw bad("empty block with first page " + std::to_string(entry.first_page) + ", expected 0");
    }
    return;
  }
  // Data pages are [1, data_end_page): page 0 is the header, the index follows.
  if (entry.first_page < 1 || entry.first_page >= data_end_page ||
      data_end_page - entry.first_page < entry.page_count) {
    throw bad("pages [" + std::to_string(entry.first_page) + ", " +
              std::to_string(entry.first_page + entry.page_count) + ") are outside the data pages [1, " +
              std::to_string(data_end_page) + ")");
  }
}

IndexPage DecodeIndexPage(std::span<const std::uint8_t> page, const IndexPageExpectation& expect) {
  auto bad = [&](const std::string& what) {
    return Error::Corruption(expect.path, "index page " + std::to_string(expect.page_number) + " (epoch " +
                                              std::to_string(expect.epoch) + "): " + what);
  };
  const std::uint8_t* in = page.data();
  if (!std::equal(kIndexPageMagic.begin(), kIndexPageMagic.end(), in + page_offset::kMagic)) {
    throw bad("wrong magic: expected \"OCIX\"");
  }
  const std::uint8_t kind = in[page_offset::kKind];
  const bool leaf = expect.level == 0;
  const std::size_t entry_size = leaf ? kLeafEntrySize : kInteriorEntrySize;
  const std::size_t capacity = leaf ? LeafCapacity(expect.page_size) : InteriorCapacity(expect.page_size);
  const std::uint32_t count = GetU32(in + page_offset::kEntryCount);
  // The count bounds the checksummed range, so check it first; a corrupted
  // count is then reported as such rather than read past the page.
  if (count == 0 || count > capacity) {
    throw bad("entry count " + std::to_string(count) + " is not in [1, " + std::to_string(capacity) + "]");
  }
  std::uint64_t stored = GetU64(in + page_offset::kChecksum);
  std::uint64_t computed = IndexPageChecksum(page, count * entry_size);
  if (stored != computed) {
    throw bad("checksum mismatch: stored " + Hex64(stored) + ", computed " + Hex64(computed));
  }
  if (kind != (leaf ? kLeafPageKind : kInteriorPageKind) || in[page_offset::kLevel] != expect.level) {
    throw bad("kind " + std::to_string(kind) + " level " + std::to_string(in[page_offset::kLevel]) +
              ", expected level " + std::to_string(expect.level));
  }
  if (GetU16(in + page_offset::kReserved16) != 0 || GetU32(in + page_offset::kReserved32) != 0) {
    throw bad("reserved bytes are not zero");
  }
  std::uint64_t self = GetU64(in + page_offset::kPageNumber);
  if (self != expect.page_number) {
    throw bad("page says it is page " + std::to_string(self) + " (misdirected write?)");
  }

  IndexPage result;
  result.page_number = expect.page_number;
  result.level = expect.level;
  if (leaf) {
    result.leaf_entries.reserve(count);
  } else {
    result.interior_entries.reserve(count);
  }
  const std::uint8_t* entries = in + kIndexPageHeaderSize;
  std::uint64_t previous_key = 0;
  for (std::uint32_t i = 0; i < count; ++i) {
    const std::uint8_t* e = entries + i * entry_size;
    std::uint64_t key = GetU64(e);
    if (i > 0 && key <= previous_key) {
      throw bad("keys out of order: " + Hex64(key) + " after " + Hex64(previous_key));
    }
    previous_key = key;
    if (leaf) {
      IndexEntry entry;
      entry.key = key;
      entry.first_page = GetU64(e + leaf_offset::kFirstPage);
      entry.byte_length = GetU64(e + leaf_offset::kByteLength);
      entry.point_count = GetU64(e + leaf_offset::kPointCount);
      entry.checksum = GetU64(e + leaf_offset::kChecksum);
      entry.page_count = GetU32(e + leaf_offset::kPageCount);
      if (GetU32(e + leaf_offset::kReserved) != 0) {
        throw bad("reserved bytes of the entry for block " + Hex64(key) + " are not zero");
      }
      CheckIndexEntry(entry, expect.page_size, expect.layout.first_page, expect.path, expect.epoch);
      result.leaf_entries.push_back(entry);
    } else {
      InteriorEntry entry{key, GetU64(e + 8)};
      const IndexLayout& layout = expect.layout;
      if (entry.child_page < layout.first_page || entry.child_page >= layout.first_page + layout.page_count) {
        throw bad("child page " + std::to_string(entry.child_page) + " is outside the index pages");
      }
      result.interior_entries.push_back(entry);
    }
  }
  return result;
}

}  // namespace octocosm
