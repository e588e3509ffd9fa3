// Reads one page file (docs/FORMAT.md section 2): checks the header at open,
// finds blocks through the B+-tree index, and reads each block with a single
// positioned read, verified against its checksum before it is returned.
//
// The file is local or on an HTTP server (storage/http_file.h).
// Thread-safe: reads are positioned (no file offset), and the index cache
// has its own lock. Open reads only the 128-byte header.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "storage/block_index_reader.h"
#include "storage/block_source.h"
#include "storage/file.h"
#include "storage/page_file_format.h"

namespace octocosm {

// Counters of what a reader has read from its file(s); a snapshot.
struct ReaderStats {
  std::uint64_t header_reads = 0;
  std::uint64_t index_page_reads = 0;   // index pages read from the file
  std::uint64_t index_cache_hits = 0;   // index pages found decoded in the cache
  std::uint64_t block_reads = 0;        // positioned reads of blocks
  std::uint64_t bytes_read = 0;         // all bytes read: header, index pages, blocks

  ReaderStats& operator+=(const ReaderStats& other);
};

class PageFileReader {
 public:
  struct Options {
    std::size_t index_cache_pages = 64;
  };

  // Opens `path` (a path or an http(s) URL) and checks its header and size.
  // kNotFound if the file does not exist; kCorruption / kNotSupported for a
  // bad file; kIo if the OS or the server fails.
  static std::unique_ptr<PageFileReader> Open(const std::string& path, Options options);
  static std::unique_ptr<PageFileReader> Open(const std::string& path) { return Open(path, Options{}); }

  PageFileReader(const PageFileReader&) = delete;
  PageFileReader& operator=(const PageFileReader&) = delete;

  const PageFileHeader& header() const { return header_; }
  const std::string& path() const { return file_->path(); }
  std::uint32_t epoch() const { return header_.epoch; }
  std::uint64_t block_count() const { return header_.block_count; }
  std::uint32_t page_size() const { return header_.page_size; }
  // The file is on a server (ReadableFile::remote).
  bool remote() const { return file_->remote(); }

  std::optional<IndexEntry> Lookup(std::uint64_t key) const;
  // Visits the entries with keys in [lo, hi] in key order until `visit`
  // returns false.
  void Scan(std::uint64_t lo, std::uint64_t hi, const std::function<bool(const IndexEntry&)>& visit) const;

  // Reads the block described by `entry` (from Lookup or Scan of this file)
  // into `out`, which must hold at least entry.byte_length bytes, and verifies
  // it. No allocation. Throws kCorruption on a checksum mismatch or a file
  // that ends early (the contents of `out` are then unspecified), kIo if the
  // OS fails, kInvalidArgument if `out` is too small.
  void ReadBlockInto(const IndexEntry& entry, std::span<std::uint8_t> out) const;
  // The same for several blocks, given in ascending order of offset, each
  // into its own buffer: from a server with one request for all (the pages
  // between them are fetched and dropped; ReadableFile::ReadRanges). Throws
  // for the first block that fails; the buffers are then unspecified.
  void ReadBlocksInto(std::span<const IndexEntry> entries, std::span<const std::span<std::uint8_t>> outs) const;
  // Where a block starts in the file.
  std::uint64_t BlockOffset(const IndexEntry& entry) const { return entry.first_page * header_.page_size; }
  // Reads bytes [offset, offset + out.size()) of a block WITHOUT verifying
  // them: the block checksum covers the whole block only. For callers whose
  // payload carries its own checksums for the parts they read (the block
  // codec checksums its header and each column), so they can skip what they
  // do not need. kInvalidArgument when the range exceeds the block.
  void ReadBlockRange(const IndexEntry& entry, std::uint64_t offset, std::span<std::uint8_t> out) const;
  Bytes ReadBlock(const IndexEntry& entry) const;
  // Looks up and reads; kNotFound if there is no block with this key.
  Bytes ReadBlock(std::uint64_t key) const;

  // Drops the file from the OS page cache (for cold-read benchmarks) and
  // forgets cached index pages but the root.
  void DropCaches() const;
  // Hints a front-to-back read of the file (e.g. a full scan).
  void AdviseSequential() const { file_->AdviseSequential(); }

  ReaderStats stats() const;
  std::uint32_t index_height() const { return header_.index.height; }

 private:
  PageFileReader(std::unique_ptr<ReadableFile> file, const PageFileHeader& header, Options options);
  void ReadIndexPage(std::uint64_t page_number, std::span<std::uint8_t> out) const;
  std::string BlockLabel(std::uint64_t key) const;
  // Throws kInvalidArgument unless `out` holds the block.
  void CheckBuffer(const IndexEntry& entry, std::span<const std::uint8_t> out) const;
  // Throws kCorruption for a block read short (`got` of bytes.size() bytes)
  // or failing its checksum.
  void VerifyBlock(const IndexEntry& entry, std::span<const std::uint8_t> bytes, std::size_t got) const;

  std::unique_ptr<ReadableFile> file_;
  const PageFileHeader header_;
  BlockIndexReader index_;
  mutable std::atomic<std::uint64_t> bytes_read_{0};
  mutable std::atomic<std::uint64_t> block_reads_{0};
};

}  // namespace octocosm
