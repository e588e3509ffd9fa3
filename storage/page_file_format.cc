#include "storage/page_file_format.h"

#include <algorithm>

#include "base/error.h"
#include "storage/block_index_format.h"
#include "storage/checksum.h"
#include "storage/coding.h"

namespace octocosm {

bool IsValidPageSize(std::uint64_t page_size) {
  return page_size >= kMinPageSize && page_size <= kMaxPageSize && (page_size & (page_size - 1)) == 0;
}

std::array<std::uint8_t, kPageFileHeaderSize> PageFileHeader::Encode() const {
  namespace off = header_offset;
  std::array<std::uint8_t, kPageFileHeaderSize> out{};
  std::copy(kPageFileMagic.begin(), kPageFileMagic.end(), out.begin() + off::kMagic);
  PutU32(&out[off::kFormatVersion], kPageFileFormatVersion);
  PutU32(&out[off::kPageSize], page_size);
  PutU64(&out[off::kStoreId], store_id);
  PutU32(&out[off::kEpoch], epoch);
  PutU32(&out[off::kFlags], 0);
  PutU64(&out[off::kBlockCount], block_count);
  PutU64(&out[off::kTotalPageCount], total_page_count);
  PutU64(&out[off::kIndexFirstPage], index.first_page);
  PutU64(&out[off::kIndexPageCount], index.page_count);
  PutU64(&out[off::kIndexLeafPageCount], index.leaf_page_count);
  PutU64(&out[off::kIndexRootPage], index.root_page);
  PutU32(&out[off::kIndexHeight], index.height);
  PutU32(&out[off::kHeaderSize], kPageFileHeaderSize);
  PutU64(&out[off::kChecksum], Checksum64(std::span<const std::uint8_t>(out.data(), off::kChecksum)));
  return out;
}

PageFileHeader PageFileHeader::Decode(std::span<const std::uint8_t> bytes, const std::string& path) {
  namespace off = header_offset;
  const std::uint8_t* in = bytes.data();
  if (bytes.size() < kPageFileHeaderSize) {
    throw Error::Corruption(path, "truncated: the file is " + std::to_string(bytes.size()) +
                                      " bytes, shorter than the " + std::to_string(kPageFileHeaderSize) +
                                      "-byte page file header");
  }
  if (!std::equal(kPageFileMagic.begin(), kPageFileMagic.end(), in + off::kMagic)) {
    throw Error::Corruption(path, "wrong magic: expected \"OCTOPAGE\" at offset 0; not an octocosm page file");
  }
  // The version comes before the checksum: a later version may checksum a
  // different header, and the honest answer to it is "not supported".
  std::uint32_t version = GetU32(in + off::kFormatVersion);
  if (version != kPageFileFormatVersion) {
    throw Error::NotSupported(path, "page file format version " + std::to_string(version) +
                                        "; this build reads version " +
                                        std::to_string(kPageFileFormatVersion));
  }
  std::uint64_t stored = GetU64(in + off::kChecksum);
  std::uint64_t computed = Checksum64(bytes.first(off::kChecksum));
  if (stored != computed) {
    throw Error::Corruption(path, "header checksum mismatch: stored " + Hex64(stored) + ", computed " +
                                      Hex64(computed));
  }
  std::uint32_t flags = GetU32(in + off::kFlags);
  if (flags != 0) {
    throw Error::NotSupported(path, "header flags " + Hex64(flags) + ": no flags are defined in version 1");
  }
  if (std::any_of(in + off::kReserved, in + off::kChecksum, [](std::uint8_t b) { return b != 0; })) {
    throw Error::Corruption(path, "reserved header bytes 88..119 are not zero");
  }

  PageFileHeader header;
  header.page_size = GetU32(in + off::kPageSize);
  header.store_id = GetU64(in + off::kStoreId);
  header.epoch = GetU32(in + off::kEpoch);
  header.block_count = GetU64(in + off::kBlockCount);
  header.total_page_count = GetU64(in + off::kTotalPageCount);
  header.index.first_page = GetU64(in + off::kIndexFirstPage);
  header.index.page_count = GetU64(in + off::kIndexPageCount);
  header.index.leaf_page_count = GetU64(in + off::kIndexLeafPageCount);
  header.index.root_page = GetU64(in + off::kIndexRootPage);
  header.index.height = GetU32(in + off::kIndexHeight);
  std::uint32_t header_size = GetU32(in + off::kHeaderSize);

  auto bad = [&](const std::string& what) { return Error::Corruption(path, "bad header: " + what); };
  if (!IsValidPageSize(header.page_size)) {
    throw bad("page size " + std::to_string(header.page_size) +
              " is not a power of two in [4096, 16777216]");
  }
  if (header_size != kPageFileHeaderSize) {
    throw bad("header size field is " + std::to_string(header_size) + ", expected 128");
  }
  if (header.total_page_count == 0 || header.total_page_count > (std::uint64_t{1} << 63) / header.page_size) {
    throw bad("total page count " + std::to_string(header.total_page_count) + " is impossible");
  }
  // The bulk-load rule fixes the index shape from the block count alone, so
  // the geometry can be checked exactly before any index page is read.
  const std::uint64_t max_blocks = header.total_page_count * LeafCapacity(header.page_size);
  if (header.block_count > max_blocks) {
    throw bad("block count " + std::to_string(header.block_count) + " cannot fit in " +
              std::to_string(header.total_page_count) + " pages");
  }
  IndexShape shape = ComputeIndexShape(header.block_count, header.page_size);
  const IndexLayout& index = header.index;
  if (index.page_count != shape.total_pages() || index.leaf_page_count != shape.leaf_pages() ||
      index.height != shape.height()) {
    throw bad("index geometry (" + std::to_string(index.page_count) + " pages, " +
              std::to_string(index.leaf_page_count) + " leaves, height " + std::to_string(index.height) +
              ") does not match " + std::to_string(header.block_count) + " blocks (expected " +
              std::to_string(shape.total_pages()) + " pages, " + std::to_string(shape.leaf_pages()) +
              " leaves, height " + std::to_string(shape.height()) + ")");
  }
  if (index.first_page < 1 || index.first_page > header.total_page_count ||
      header.total_page_count - index.first_page != index.page_count) {
    throw bad("index pages [" + std::to_string(index.first_page) + ", +" + std::to_string(index.page_count) +
              ") do not end the file of " + std::to_string(header.total_page_count) + " pages");
  }
  std::uint64_t expected_root = index.page_count == 0 ? 0 : header.total_page_count - 1;
  if (index.root_page != expected_root) {
    throw bad("index root page " + std::to_string(index.root_page) + ", expected " +
              std::to_string(expected_root));
  }
  return header;
}

}  // namespace octocosm
