// Writes one page file (docs/FORMAT.md section 2): blocks appended in the
// caller's order, each on its own run of pages, then the bulk-loaded index,
// then the header. Several threads may add blocks at once: each takes its
// pages under a lock and writes them outside it, with direct I/O on a
// background thread where the file system allows it (storage/direct_writer.h).
// Crash-safe: everything goes to `<path>.tmp`, which is fsynced and renamed
// to `<path>` only by Finish(), followed by an fsync of the directory. A
// writer destroyed before Finish() removes its .tmp file.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <unordered_set>
#include <vector>

#include "base/mutex.h"
#include "storage/block_index_format.h"
#include "storage/direct_writer.h"
#include "storage/file.h"
#include "storage/page_file_format.h"
#include "storage/page_file_reader.h"

namespace octocosm {

class PageFileWriter {
 public:
  struct Summary {
    std::uint64_t block_count = 0;
    std::uint64_t file_size = 0;
  };

  // Creates `path`.tmp. `page_size` must be a power of two in [4 KiB, 16 MiB]
  // (kInvalidArgument otherwise).
  PageFileWriter(std::string path, std::uint32_t page_size, std::uint64_t store_id, std::uint32_t epoch);
  PageFileWriter(const PageFileWriter&) = delete;
  PageFileWriter& operator=(const PageFileWriter&) = delete;
  ~PageFileWriter();

  // Appends one block; may be called from several threads at once. Keys may
  // come in any order; a key added twice is kInvalidArgument (and the writer
  // stays usable). `point_count` is stored in the index for the caller's
  // use. A write may finish after AddBlock returns, so its failure (kIo)
  // comes from a later AddBlock or from Finish; after it the writer refuses
  // further blocks and Finish.
  void AddBlock(std::uint64_t key, std::span<const std::uint8_t> bytes, std::uint64_t point_count) EXCLUDES(mutex_);

  // Makes room for every block of `source`, a finished page file of this page
  // size, store and epoch, and adds their index entries, moved to the pages
  // they take here. Their bytes are then copied as they are (CopyBlockPages,
  // from the returned byte offset on), by this process or by another that
  // sees this writer's temporary file, and must be there before Finish, which
  // cannot check. So an epoch whose blocks several processes built is put
  // together without reading and writing each block again, and each process
  // may copy its own. Another page size, store or epoch, or a key already
  // added, is kInvalidArgument (nothing is added).
  std::uint64_t ReserveBlocksOf(const PageFileReader& source) EXCLUDES(mutex_);

  // Writes the index and header, makes the file durable and gives it its
  // final name. The writer cannot be used afterwards. Every AddBlock must
  // have returned, so it reads the members mutex_ guards unlocked.
  Summary Finish() NO_THREAD_SAFETY_ANALYSIS;

  // Bytes written to the file so far (data pages with padding, header page,
  // and after Finish the index pages). Not while blocks are being added.
  std::uint64_t bytes_written() const { return file_ ? file_->size() : finished_size_; }
  std::uint64_t block_count() const NO_THREAD_SAFETY_ANALYSIS { return entries_.size(); }
  const std::string& path() const { return path_; }
  std::string temporary_path() const { return path_ + ".tmp"; }

 private:
  void RequireOpen(const char* operation) const;
  void RequireNoFailedWrite(const char* operation) const REQUIRES(mutex_);

  const std::string path_;
  const std::uint32_t page_size_;
  const std::uint64_t store_id_;
  const std::uint32_t epoch_;
  std::optional<WritableFile> file_;  // empty once finished
  std::unique_ptr<DirectWriter> direct_;  // blocks' writes; null where direct I/O is refused
  std::uint64_t finished_size_ = 0;
  Mutex mutex_;  // guards the members below, and file_'s end during AddBlock
  std::uint64_t next_page_ GUARDED_BY(mutex_) = 1;  // page 0 is the header
  std::vector<IndexEntry> entries_ GUARDED_BY(mutex_);  // in the order added
  std::unordered_set<std::uint64_t> keys_ GUARDED_BY(mutex_);
  bool failed_write_ GUARDED_BY(mutex_) = false;
};

// Copies the blocks' pages of the finished page file `source` as they are into
// `target` at `offset`, where PageFileWriter::ReserveBlocksOf made room for
// them in the temporary file of another page file's writer, and makes them
// durable.
void CopyBlockPages(const std::string& source, const std::string& target, std::uint64_t offset);

}  // namespace octocosm
