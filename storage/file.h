// The storage layer's one seam to the operating system: files read with
// positioned reads, files written sequentially, and the directory operations
// a crash-safe commit needs (rename, directory fsync).
//
// Every failure of a system call becomes Error kIo naming the path and the
// call. Deciding whether a short read means corruption is left to the caller,
// which knows how long the file should be.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace octocosm {

// Owns a file descriptor; closes it on destruction.
class UniqueFd {
 public:
  UniqueFd() = default;
  explicit UniqueFd(int fd) : fd_(fd) {}
  UniqueFd(UniqueFd&& other) noexcept : fd_(other.Release()) {}
  UniqueFd& operator=(UniqueFd&& other) noexcept;
  UniqueFd(const UniqueFd&) = delete;
  UniqueFd& operator=(const UniqueFd&) = delete;
  ~UniqueFd();

  int get() const { return fd_; }
  bool valid() const { return fd_ >= 0; }
  int Release() {
    int fd = fd_;
    fd_ = -1;
    return fd;
  }

 private:
  int fd_ = -1;
};

// One range of a ReadableFile::ReadRanges call.
struct RangeRead {
  std::uint64_t offset = 0;
  std::span<std::uint8_t> out;
  std::size_t got = 0;  // set by ReadRanges: bytes read, fewer than out.size() only where the file ends
};

// A read-only file read at offsets, by any number of threads at once: a local
// file (RandomAccessFile) or one on an HTTP server (HttpFile, storage/http_file.h).
class ReadableFile {
 public:
  virtual ~ReadableFile() = default;
  // Reads up to out.size() bytes at `offset`; fewer only where the file ends.
  // Returns the number of bytes read.
  virtual std::size_t ReadAt(std::uint64_t offset, std::span<std::uint8_t> out) const = 0;
  // Reads several ranges, given in ascending order of offset and not
  // overlapping (kInvalidArgument otherwise). A remote file fetches those it
  // does not hold with one request from the first one's start to the last
  // one's end, the bytes between them fetched and dropped (the caller keeps
  // the gaps small); a local one reads each.
  virtual void ReadRanges(std::span<RangeRead> ranges) const;
  virtual std::uint64_t Size() const = 0;
  // The path or URL, for messages.
  virtual const std::string& path() const = 0;
  // True where each read is a round trip to a server: one read of a whole
  // block then costs less than two of its parts.
  virtual bool remote() const { return false; }
  // Caching hints; files without an OS page cache ignore them.
  virtual void DropFromPageCache() const {}
  virtual void AdviseSequential() const {}
  virtual void AdviseRandom() const {}
  // Declares a range that will be read often in small pieces (a page file's
  // index). A remote file fetches it whole at the first read inside it and
  // keeps it; a local one leaves it to the OS page cache. Called once, before
  // reads from several threads begin.
  virtual void KeepResident(std::uint64_t /*offset*/, std::uint64_t /*length*/) {}
};

// kInvalidArgument naming `path` unless the ranges ascend without overlapping
// (ReadableFile::ReadRanges).
void CheckAscendingRanges(std::span<const RangeRead> ranges, const std::string& path);

// A local read-only file read with pread: no shared file offset, so one
// object may serve any number of threads at once.
class RandomAccessFile final : public ReadableFile {
 public:
  // Throws kNotFound if the file does not exist, kIo on other failures.
  static RandomAccessFile Open(const std::string& path);

  RandomAccessFile(RandomAccessFile&&) noexcept = default;
  RandomAccessFile& operator=(RandomAccessFile&&) noexcept = default;

  // Retries interrupted and partial reads.
  std::size_t ReadAt(std::uint64_t offset, std::span<std::uint8_t> out) const override;

  // The current size of the file (fstat).
  std::uint64_t Size() const override;

  // Asks the kernel to drop this file's cached pages (POSIX_FADV_DONTNEED),
  // so the next reads are cold. Only clean pages can be dropped, which is all
  // of them for a file this process only reads.
  void DropFromPageCache() const override;
  // Hints that the file will be read front to back (larger read-ahead).
  void AdviseSequential() const override;
  // Hints that reads are scattered (no read-ahead): the default for a store.
  void AdviseRandom() const override;

  const std::string& path() const override { return path_; }

 private:
  RandomAccessFile(std::string path, UniqueFd fd) : path_(std::move(path)), fd_(std::move(fd)) {}
  void Advise(int advice, const char* name) const;

  std::string path_;
  UniqueFd fd_;
};

// A file written front to back through a buffer, with one positioned write
// for patching a header at the end, and ranges reserved at the end to be
// filled by several threads at once (ReserveRange, WriteUnbufferedAt).
// Create truncates an existing file.
class WritableFile {
 public:
  static WritableFile Create(const std::string& path);

  WritableFile(WritableFile&&) noexcept = default;
  WritableFile& operator=(WritableFile&&) noexcept = default;
  // Closes the descriptor if Close() was not called; errors are dropped there,
  // so callers that care call Close().
  ~WritableFile() = default;

  void Append(std::span<const std::uint8_t> bytes);
  // Appends `count` zero bytes; runs of 4 KiB or more become a hole (a
  // sparse file where the file system has them), which reads back the same.
  void AppendZeros(std::uint64_t count);
  // Writes at an absolute offset (after flushing what was appended).
  void WriteAt(std::uint64_t offset, std::span<const std::uint8_t> bytes);
  // Moves the end of the file `count` bytes on without writing, as a hole
  // that reads as zeros where nothing is written into it; returns where the
  // range starts.
  std::uint64_t ReserveRange(std::uint64_t count);
  // Writes `bytes` at `offset`, straight to the file. Unlike the calls above
  // it may run on several threads at once, for ranges that overlap neither
  // each other nor what the calls above write: ranges from ReserveRange.
  void WriteUnbufferedAt(std::uint64_t offset, std::span<const std::uint8_t> bytes) const;
  // Flushes the buffer and fsyncs the file.
  void Sync();
  // Flushes and closes; reports a failed close (NFS reports write errors there).
  void Close();

  // Bytes appended so far: the file size once flushed.
  std::uint64_t size() const { return size_; }
  const std::string& path() const { return path_; }

 private:
  WritableFile(std::string path, UniqueFd fd) : path_(std::move(path)), fd_(std::move(fd)) {}
  void Flush();
  void ExtendOverTrailingHole();

  std::string path_;
  UniqueFd fd_;
  std::vector<std::uint8_t> buffer_;
  std::uint64_t flushed_ = 0;  // file offset where buffer_ starts
  std::uint64_t size_ = 0;
};

// pwrite(2) of all of `bytes` at `offset`, retrying interrupted and partial
// writes. Returns 0, or the errno of the write that failed (the caller names
// the file in its error, or tries another way).
int WriteAllAt(int fd, std::uint64_t offset, std::span<const std::uint8_t> bytes);
// The same for `parts` written one after another from `offset` (pwritev(2),
// at most IOV_MAX parts a call).
int WriteAllAt(int fd, std::uint64_t offset, std::span<const std::span<const std::uint8_t>> parts);

// Copies `length` bytes of the file `from`, starting at `from_offset`, into
// the existing file `to` at `to_offset` (copy_file_range(2), where the kernel
// copies without this process's memory, else reads and writes), then
// fdatasyncs `to`. kIo naming the file whose call failed, kCorruption if
// `from` ends before the range does.
void CopyFileRange(const std::string& from, std::uint64_t from_offset, const std::string& to,
                   std::uint64_t to_offset, std::uint64_t length);

// rename(2): atomically replaces `to` on the same file system.
void RenameFile(const std::string& from, const std::string& to);
// fsync on the directory, so that renames and creations in it are durable.
void SyncDirectory(const std::string& directory);
// Creates the directory (and missing parents); fine if it exists already.
void CreateDirectories(const std::string& directory);
// Removes a file; a missing file is not an error. Never throws: used during
// clean-up, where the first error is the one to report.
void RemoveFileQuietly(const std::string& path) noexcept;
bool PathExists(const std::string& path);
bool IsDirectory(const std::string& path);
// Names (not paths) of the entries in a directory, sorted.
std::vector<std::string> ListDirectory(const std::string& directory);
// `directory` + "/" + `name`.
std::string JoinPath(const std::string& directory, const std::string& name);

}  // namespace octocosm
