// The page-file header (page 0) of docs/FORMAT.md section 2.2, as a struct
// with an encoder and a checking decoder. The constants mirror the spec's
// table; change one only together with FORMAT.md and the format version.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>

namespace octocosm {

inline constexpr std::array<std::uint8_t, 8> kPageFileMagic = {'O', 'C', 'T', 'O', 'P', 'A', 'G', 'E'};
inline constexpr std::uint32_t kPageFileFormatVersion = 1;
inline constexpr std::uint32_t kPageFileHeaderSize = 128;
inline constexpr std::uint32_t kMinPageSize = 4 * 1024;
inline constexpr std::uint32_t kMaxPageSize = 16 * 1024 * 1024;
inline constexpr std::uint32_t kDefaultPageSize = 4 * 1024;

// Field offsets within the header record.
namespace header_offset {
inline constexpr std::size_t kMagic = 0;
inline constexpr std::size_t kFormatVersion = 8;
inline constexpr std::size_t kPageSize = 12;
inline constexpr std::size_t kStoreId = 16;
inline constexpr std::size_t kEpoch = 24;
inline constexpr std::size_t kFlags = 28;
inline constexpr std::size_t kBlockCount = 32;
inline constexpr std::size_t kTotalPageCount = 40;
inline constexpr std::size_t kIndexFirstPage = 48;
inline constexpr std::size_t kIndexPageCount = 56;
inline constexpr std::size_t kIndexLeafPageCount = 64;
inline constexpr std::size_t kIndexRootPage = 72;
inline constexpr std::size_t kIndexHeight = 80;
inline constexpr std::size_t kHeaderSize = 84;
inline constexpr std::size_t kReserved = 88;
inline constexpr std::size_t kChecksum = 120;
}  // namespace header_offset

bool IsValidPageSize(std::uint64_t page_size);

// Where the static B+-tree lives in a page file (docs/FORMAT.md 2.5).
struct IndexLayout {
  std::uint64_t first_page = 0;
  std::uint64_t page_count = 0;
  std::uint64_t leaf_page_count = 0;
  std::uint64_t root_page = 0;
  std::uint32_t height = 0;

  friend bool operator==(const IndexLayout&, const IndexLayout&) = default;
};

struct PageFileHeader {
  std::uint32_t page_size = kDefaultPageSize;
  std::uint64_t store_id = 0;
  std::uint32_t epoch = 0;
  std::uint64_t block_count = 0;
  std::uint64_t total_page_count = 0;
  IndexLayout index;

  std::array<std::uint8_t, kPageFileHeaderSize> Encode() const;

  // Decodes and checks a header read from `path` (magic, version, checksum,
  // flags, reserved bytes, page size, index geometry): everything that can be
  // checked without the file size. Throws kCorruption or kNotSupported with
  // a message naming `path`. `bytes` must hold kPageFileHeaderSize bytes.
  static PageFileHeader Decode(std::span<const std::uint8_t> bytes, const std::string& path);

  std::uint64_t file_size() const { return total_page_count * page_size; }
};

}  // namespace octocosm
