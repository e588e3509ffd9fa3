#include "storage/page_file_reader.h"

#include <array>
#include <vector>

#include "base/error.h"
#include "storage/checksum.h"
#include "storage/http_file.h"

namespace octocosm {

ReaderStats& ReaderStats::operator+=(const ReaderStats& other) {
  header_reads += other.header_reads;
  index_page_reads += other.index_page_reads;
  index_cache_hits += other.index_cache_hits;
  block_reads += other.block_reads;
  bytes_read += other.bytes_read;
  return *this;
}

std::unique_ptr<PageFileReader> PageFileReader::Open(const std::string& path, Options options) {
  std::unique_ptr<ReadableFile> file = OpenReadableFile(path);
  std::array<std::uint8_t, kPageFileHeaderSize> bytes{};
  std::size_t got = file->ReadAt(0, bytes);
  PageFileHeader header = PageFileHeader::Decode(std::span<const std::uint8_t>(bytes.data(), got), path);
  const std::uint64_t actual = file->Size();
  if (actual != header.file_size()) {
    throw Error::Corruption(path, std::string(actual < header.file_size() ? "truncated" : "trailing bytes") +
                                      ": the file is " + std::to_string(actual) + " bytes, the header says " +
                                      std::to_string(header.total_page_count) + " pages of " +
                                      std::to_string(header.page_size) + " = " +
                                      std::to_string(header.file_size()) + " bytes");
  }
  // Blocks are found through the index and read one by one: disable
  // read-ahead, which would only pull in neighbours nobody asked for.
  file->AdviseRandom();
  // Lookups read the index a page at a time; over a network each page would
  // cost a round trip.
  file->KeepResident(header.index.first_page * header.page_size, header.index.page_count * header.page_size);
  std::unique_ptr<PageFileReader> reader(new PageFileReader(std::move(file), header, options));
  reader->bytes_read_ = got;
  return reader;
}

PageFileReader::PageFileReader(std::unique_ptr<ReadableFile> file, const PageFileHeader& header, Options options)
    : file_(std::move(file)),
      header_(header),
      index_(file_->path(), header.epoch, header.page_size, header.index,
             [this](std::uint64_t page_number, std::span<std::uint8_t> out) { ReadIndexPage(page_number, out); },
             BlockIndexReader::Options{options.index_cache_pages}) {}

void PageFileReader::ReadIndexPage(std::uint64_t page_number, std::span<std::uint8_t> out) const {
  const std::uint64_t offset = page_number * header_.page_size;
  std::size_t got = file_->ReadAt(offset, out);
  bytes_read_.fetch_add(got, std::memory_order_relaxed);
  if (got != out.size()) {
    throw Error::Corruption(path(), "truncated: index page " + std::to_string(page_number) + " (epoch " +
                                        std::to_string(header_.epoch) + ") at offset " + std::to_string(offset) +
                                        " is cut short at " + std::to_string(got) + " of " +
                                        std::to_string(out.size()) + " bytes");
  }
}

std::string PageFileReader::BlockLabel(std::uint64_t key) const {
  return "block " + Hex64(key) + " (epoch " + std::to_string(header_.epoch) + ")";
}

std::optional<IndexEntry> PageFileReader::Lookup(std::uint64_t key) const { return index_.Lookup(key); }

void PageFileReader::Scan(std::uint64_t lo, std::uint64_t hi,
                          const std::function<bool(const IndexEntry&)>& visit) const {
  index_.Scan(lo, hi, visit);
}

void PageFileReader::CheckBuffer(const IndexEntry& entry, std::span<const std::uint8_t> out) const {
  if (out.size() < entry.byte_length) {
    throw Error::InvalidArgument(BlockLabel(entry.key) + " of " + path() + " is " +
                                 std::to_string(entry.byte_length) + " bytes; the buffer holds " +
                                 std::to_string(out.size()));
  }
}

void PageFileReader::VerifyBlock(const IndexEntry& entry, std::span<const std::uint8_t> bytes, std::size_t got) const {
  if (got != bytes.size()) {
    throw Error::Corruption(path(), BlockLabel(entry.key) + ": truncated: expected " + std::to_string(bytes.size()) +
                                        " bytes at offset " + std::to_string(BlockOffset(entry)) +
                                        ", the file ends after " + std::to_string(got));
  }
  std::uint64_t computed = Checksum64(bytes);
  if (computed != entry.checksum) {
    throw Error::Corruption(path(), BlockLabel(entry.key) + ": checksum mismatch: stored " +
                                        Hex64(entry.checksum) + ", computed " + Hex64(computed));
  }
}

void PageFileReader::ReadBlockInto(const IndexEntry& entry, std::span<std::uint8_t> out) const {
  CheckBuffer(entry, out);
  auto bytes = out.first(static_cast<std::size_t>(entry.byte_length));
  std::size_t got = 0;
  if (!bytes.empty()) {
    // One positioned read of exactly the block: what an HTTP reader would
    // ask for as one range request.
    got = file_->ReadAt(BlockOffset(entry), bytes);
    block_reads_.fetch_add(1, std::memory_order_relaxed);
    bytes_read_.fetch_add(got, std::memory_order_relaxed);
  }
  VerifyBlock(entry, bytes, got);
}

void PageFileReader::ReadBlocksInto(std::span<const IndexEntry> entries,
                                    std::span<const std::span<std::uint8_t>> outs) const {
  if (entries.size() != outs.size()) {
    throw Error::InvalidArgument("ReadBlocksInto: " + std::to_string(entries.size()) + " blocks of " + path() +
                                 " for " + std::to_string(outs.size()) + " buffers");
  }
  std::vector<RangeRead> ranges(entries.size());
  for (std::size_t i = 0; i < entries.size(); ++i) {
    CheckBuffer(entries[i], outs[i]);
    ranges[i].offset = BlockOffset(entries[i]);
    ranges[i].out = outs[i].first(static_cast<std::size_t>(entries[i].byte_length));
  }
  file_->ReadRanges(ranges);
  std::uint64_t got = 0;
  for (const RangeRead& range : ranges) got += range.got;
  block_reads_.fetch_add(entries.size(), std::memory_order_relaxed);
  bytes_read_.fetch_add(got, std::memory_order_relaxed);
  for (std::size_t i = 0; i < entries.size(); ++i) VerifyBlock(entries[i], ranges[i].out, ranges[i].got);
}

void PageFileReader::ReadBlockRange(const IndexEntry& entry, std::uint64_t offset, std::span<std::uint8_t> out) const {
  if (offset > entry.byte_length || out.size() > entry.byte_length - offset) {
    throw Error::InvalidArgument(BlockLabel(entry.key) + " of " + path() + " is " + std::to_string(entry.byte_length) +
                                 " bytes; cannot read " + std::to_string(out.size()) + " bytes at " + std::to_string(offset));
  }
  if (out.empty()) return;
  const std::uint64_t at = entry.first_page * header_.page_size + offset;
  const std::size_t got = file_->ReadAt(at, out);
  block_reads_.fetch_add(1, std::memory_order_relaxed);
  bytes_read_.fetch_add(got, std::memory_order_relaxed);
  if (got != out.size()) {
    throw Error::Corruption(path(), BlockLabel(entry.key) + ": truncated: expected " + std::to_string(out.size()) +
                                        " bytes at offset " + std::to_string(at) + ", the file ends after " +
                                        std::to_string(got));
  }
}

Bytes PageFileReader::ReadBlock(const IndexEntry& entry) const {
  Bytes bytes(static_cast<std::size_t>(entry.byte_length));
  ReadBlockInto(entry, bytes);
  return bytes;
}

Bytes PageFileReader::ReadBlock(std::uint64_t key) const {
  std::optional<IndexEntry> entry = Lookup(key);
  if (!entry) throw Error::NotFound(BlockLabel(key) + " in " + path());
  return ReadBlock(*entry);
}

void PageFileReader::DropCaches() const {
  file_->DropFromPageCache();
  index_.ClearCache();
}

ReaderStats PageFileReader::stats() const {
  ReaderStats stats;
  stats.header_reads = 1;
  stats.index_page_reads = index_.page_reads();
  stats.index_cache_hits = index_.cache_hits();
  stats.block_reads = block_reads_.load(std::memory_order_relaxed);
  stats.bytes_read = bytes_read_.load(std::memory_order_relaxed);
  return stats;
}

}  // namespace octocosm
