#include "storage/file.h"

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <filesystem>
#include <system_error>

#include "base/error.h"

namespace octocosm {
namespace {

// Appends are gathered into writes of this size: large enough that a page
// file of small blocks costs few system calls, small enough not to matter.
constexpr std::size_t kWriteBufferBytes = 1 << 20;
// Shorter runs of zeros are written: a hole smaller than a file-system block saves nothing.
constexpr std::size_t kMinHoleBytes = 4096;

// Linux caps one read/write at just under 2 GiB; stay well below.
constexpr std::size_t kMaxIoBytes = std::size_t{1} << 30;

}  // namespace

UniqueFd& UniqueFd::operator=(UniqueFd&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = other.Release();
  }
  return *this;
}

UniqueFd::~UniqueFd() {
  if (fd_ >= 0) ::close(fd_);
}

RandomAccessFile RandomAccessFile::Open(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    int error = errno;
    if (error == ENOENT) throw Error::NotFound(path + ": no such file");
    throw IoErrorFromErrno(path, "open", error);
  }
  return RandomAccessFile(path, UniqueFd(fd));
}

void CheckAscendingRanges(std::span<const RangeRead> ranges, const std::string& path) {
  for (std::size_t i = 1; i < ranges.size(); ++i) {
    if (ranges[i].offset < ranges[i - 1].offset + ranges[i - 1].out.size()) {
      throw Error::InvalidArgument("ranges read from " + path + " must ascend without overlapping: bytes at " +
                                   std::to_string(ranges[i].offset) + " follow " +
                                   std::to_string(ranges[i - 1].out.size()) + " bytes at " +
                                   std::to_string(ranges[i - 1].offset));
    }
  }
}

void ReadableFile::ReadRanges(std::span<RangeRead> ranges) const {
  CheckAscendingRanges(ranges, path());
  for (RangeRead& range : ranges) range.got = ReadAt(range.offset, range.out);
}

std::size_t RandomAccessFile::ReadAt(std::uint64_t offset, std::span<std::uint8_t> out) const {
  std::size_t done = 0;
  while (done < out.size()) {
    std::size_t want = std::min(out.size() - done, kMaxIoBytes);
    ssize_t got = ::pread(fd_.get(), out.data() + done, want, static_cast<off_t>(offset + done));
    if (got < 0) {
      if (errno == EINTR) continue;
      throw IoErrorFromErrno(path_, "pread of " + std::to_string(out.size()) + " bytes at offset " +
                                        std::to_string(offset),
                             errno);
    }
    if (got == 0) break;  // end of file
    done += static_cast<std::size_t>(got);
  }
  return done;
}

std::uint64_t RandomAccessFile::Size() const {
  struct stat info {};
  if (::fstat(fd_.get(), &info) != 0) throw IoErrorFromErrno(path_, "fstat", errno);
  return static_cast<std::uint64_t>(info.st_size);
}

void RandomAccessFile::Advise(int advice, const char* name) const {
  // posix_fadvise returns the error number instead of setting errno.
  int error = ::posix_fadvise(fd_.get(), 0, 0, advice);
  if (error != 0) throw IoErrorFromErrno(path_, std::string("posix_fadvise(") + name + ")", error);
}

void RandomAccessFile::DropFromPageCache() const { Advise(POSIX_FADV_DONTNEED, "DONTNEED"); }
void RandomAccessFile::AdviseSequential() const { Advise(POSIX_FADV_SEQUENTIAL, "SEQUENTIAL"); }
void RandomAccessFile::AdviseRandom() const { Advise(POSIX_FADV_RANDOM, "RANDOM"); }

WritableFile WritableFile::Create(const std::string& path) {
  int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw IoErrorFromErrno(path, "create", errno);
  return WritableFile(path, UniqueFd(fd));
}

int WriteAllAt(int fd, std::uint64_t offset, std::span<const std::uint8_t> bytes) {
  const std::span<const std::uint8_t> parts[] = {bytes};
  return WriteAllAt(fd, offset, parts);
}

int WriteAllAt(int fd, std::uint64_t offset, std::span<const std::span<const std::uint8_t>> parts) {
  std::vector<iovec> pending;
  pending.reserve(parts.size());
  for (const auto& part : parts) {
    if (!part.empty()) pending.push_back({const_cast<std::uint8_t*>(part.data()), part.size()});
  }
  std::size_t first = 0;
  while (first < pending.size()) {
    const int count = static_cast<int>(std::min<std::size_t>(pending.size() - first, IOV_MAX));
    ssize_t wrote = ::pwritev(fd, &pending[first], count, static_cast<off_t>(offset));
    if (wrote < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    if (wrote == 0) return EIO;  // no progress on a regular file: do not spin
    offset += static_cast<std::uint64_t>(wrote);
    // Skip what went out: whole parts, then the front of a part cut short.
    for (auto left = static_cast<std::size_t>(wrote); left > 0;) {
      iovec& part = pending[first];
      const std::size_t taken = std::min(left, part.iov_len);
      part.iov_base = static_cast<std::uint8_t*>(part.iov_base) + taken;
      part.iov_len -= taken;
      left -= taken;
      if (part.iov_len == 0) ++first;
    }
  }
  return 0;
}

void WritableFile::WriteUnbufferedAt(std::uint64_t offset, std::span<const std::uint8_t> bytes) const {
  if (const int error = WriteAllAt(fd_.get(), offset, bytes); error != 0) {
    throw IoErrorFromErrno(path_, "pwrite of " + std::to_string(bytes.size()) + " bytes at offset " +
                                      std::to_string(offset),
                           error);
  }
}

void WritableFile::Flush() {
  if (buffer_.empty()) return;
  WriteUnbufferedAt(flushed_, buffer_);
  flushed_ += buffer_.size();
  buffer_.clear();
}

void WritableFile::Append(std::span<const std::uint8_t> bytes) {
  if (buffer_.size() + bytes.size() > kWriteBufferBytes) Flush();
  if (bytes.size() >= kWriteBufferBytes) {
    // Large blocks go straight to the file rather than through the buffer.
    WriteUnbufferedAt(flushed_, bytes);
    flushed_ += bytes.size();
  } else {
    buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  }
  size_ += bytes.size();
}

void WritableFile::AppendZeros(std::uint64_t count) {
  if (count < kMinHoleBytes) {
    static const std::vector<std::uint8_t> zeros(kMinHoleBytes, 0);
    Append(std::span<const std::uint8_t>(zeros.data(), static_cast<std::size_t>(count)));
    return;
  }
  // Skipped, not written: the gap becomes a hole, which reads as zeros but
  // costs no copy into the page cache and no disk blocks (the padding of
  // blocks to whole pages is about a fifth of a store).
  ReserveRange(count);
}

std::uint64_t WritableFile::ReserveRange(std::uint64_t count) {
  Flush();
  const std::uint64_t begin = size_;
  flushed_ += count;
  size_ += count;
  return begin;
}

// A file that ends in a hole is shorter than size() until its length is set.
// Only ever lengthened: writes from WriteUnbufferedAt are not tracked here.
void WritableFile::ExtendOverTrailingHole() {
  struct stat status {};
  if (::fstat(fd_.get(), &status) != 0) throw IoErrorFromErrno(path_, "fstat", errno);
  if (static_cast<std::uint64_t>(status.st_size) >= size_) return;
  if (::ftruncate(fd_.get(), static_cast<off_t>(size_)) != 0) {
    throw IoErrorFromErrno(path_, "ftruncate to " + std::to_string(size_) + " bytes", errno);
  }
}

void WritableFile::WriteAt(std::uint64_t offset, std::span<const std::uint8_t> bytes) {
  Flush();
  WriteUnbufferedAt(offset, bytes);
  size_ = std::max(size_, offset + bytes.size());
  flushed_ = std::max(flushed_, offset + bytes.size());
}

void WritableFile::Sync() {
  Flush();
  ExtendOverTrailingHole();
  if (::fsync(fd_.get()) != 0) throw IoErrorFromErrno(path_, "fsync", errno);
}

void WritableFile::Close() {
  Flush();
  ExtendOverTrailingHole();
  int fd = fd_.Release();
  if (fd >= 0 && ::close(fd) != 0) throw IoErrorFromErrno(path_, "close", errno);
}

namespace {

Error EndsInsideTheRange(const std::string& path, std::uint64_t offset) {
  return Error::Corruption(path, "ends at offset " + std::to_string(offset) + ", inside the range to copy");
}

// The part of CopyFileRange that copy_file_range(2) refuses (across file
// systems on older kernels, or where a file system lacks it): through a buffer.
void CopyThroughBuffer(int from_fd, const std::string& from, std::uint64_t from_offset, int to_fd,
                       const std::string& to, std::uint64_t to_offset, std::uint64_t length) {
  std::vector<std::uint8_t> buffer(std::min<std::uint64_t>(length, std::uint64_t{4} << 20));
  while (length > 0) {
    const std::size_t want = static_cast<std::size_t>(std::min<std::uint64_t>(length, buffer.size()));
    const ssize_t got = ::pread(from_fd, buffer.data(), want, static_cast<off_t>(from_offset));
    if (got < 0) {
      if (errno == EINTR) continue;
      throw IoErrorFromErrno(from, "pread at offset " + std::to_string(from_offset), errno);
    }
    if (got == 0) throw EndsInsideTheRange(from, from_offset);
    const std::span<const std::uint8_t> piece(buffer.data(), static_cast<std::size_t>(got));
    if (const int error = WriteAllAt(to_fd, to_offset, piece); error != 0) {
      throw IoErrorFromErrno(to, "pwrite of " + std::to_string(piece.size()) + " bytes at offset " +
                                     std::to_string(to_offset), error);
    }
    from_offset += piece.size();
    to_offset += piece.size();
    length -= piece.size();
  }
}

}  // namespace

void CopyFileRange(const std::string& from, std::uint64_t from_offset, const std::string& to,
                   std::uint64_t to_offset, std::uint64_t length) {
  const int from_fd = ::open(from.c_str(), O_RDONLY | O_CLOEXEC);
  if (from_fd < 0) throw IoErrorFromErrno(from, "open", errno);
  const UniqueFd from_owned(from_fd);
  const int to_fd = ::open(to.c_str(), O_WRONLY | O_CLOEXEC);
  if (to_fd < 0) throw IoErrorFromErrno(to, "open", errno);
  UniqueFd to_owned(to_fd);
  while (length > 0) {
    auto in = static_cast<off_t>(from_offset), out = static_cast<off_t>(to_offset);
    const std::size_t want = static_cast<std::size_t>(std::min<std::uint64_t>(length, std::uint64_t{1} << 30));
    const ssize_t copied = ::copy_file_range(from_fd, &in, to_fd, &out, want, 0);
    if (copied < 0) {
      if (errno == EINTR) continue;
      if (errno == EXDEV || errno == ENOSYS || errno == EINVAL || errno == EOPNOTSUPP) {
        CopyThroughBuffer(from_fd, from, from_offset, to_fd, to, to_offset, length);
        break;
      }
      throw IoErrorFromErrno(to, "copy_file_range of " + std::to_string(want) + " bytes from " + from, errno);
    }
    if (copied == 0) throw EndsInsideTheRange(from, from_offset);
    from_offset += static_cast<std::uint64_t>(copied);
    to_offset += static_cast<std::uint64_t>(copied);
    length -= static_cast<std::uint64_t>(copied);
  }
  if (::fdatasync(to_fd) != 0) throw IoErrorFromErrno(to, "fdatasync", errno);
  const int fd = to_owned.Release();
  if (::close(fd) != 0) throw IoErrorFromErrno(to, "close", errno);
}

void RenameFile(const std::string& from, const std::string& to) {
  if (::rename(from.c_str(), to.c_str()) != 0) {
    throw IoErrorFromErrno(from, "rename to " + to, errno);
  }
}

void SyncDirectory(const std::string& directory) {
  int fd = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) throw IoErrorFromErrno(directory, "open directory", errno);
  UniqueFd owned(fd);
  if (::fsync(owned.get()) != 0) throw IoErrorFromErrno(directory, "fsync directory", errno);
}

void CreateDirectories(const std::string& directory) {
  std::error_code error;
  std::filesystem::create_directories(directory, error);
  if (error) throw Error::Io(directory, "create directory failed: " + error.message());
}

void RemoveFileQuietly(const std::string& path) noexcept { ::unlink(path.c_str()); }

bool PathExists(const std::string& path) {
  struct stat info {};
  return ::stat(path.c_str(), &info) == 0;
}

bool IsDirectory(const std::string& path) {
  struct stat info {};
  return ::stat(path.c_str(), &info) == 0 && S_ISDIR(info.st_mode);
}

std::vector<std::string> ListDirectory(const std::string& directory) {
  DIR* dir = ::opendir(directory.c_str());
  if (dir == nullptr) throw IoErrorFromErrno(directory, "opendir", errno);
  std::vector<std::string> names;
  errno = 0;
  while (const dirent* entry = ::readdir(dir)) {
    std::string name = entry->d_name;
    if (name != "." && name != "..") names.push_back(std::move(name));
  }
  int error = errno;
  ::closedir(dir);
  if (error != 0) throw IoErrorFromErrno(directory, "readdir", error);
  std::sort(names.begin(), names.end());
  return names;
}

std::string JoinPath(const std::string& directory, const std::string& name) {
  if (directory.empty() || directory.back() == '/') return directory + name;
  return directory + "/" + name;
}

}  // namespace octocosm
