#include "ingest/snapshot/binary_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <utility>

#include "base/error.h"
#include "ingest/snapshot/file_set.h"

namespace octocosm {

BinaryFile::BinaryFile(std::string path) : path_(std::move(path)) {
  // Says what a directory, device or FIFO is before opening it (an open of a
  // FIFO would wait for a writer); O_NONBLOCK keeps that so should one be put
  // there meanwhile, and changes nothing for a regular file.
  RequireRegularFile(path_);
  fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd_ < 0) {
    int error = errno;
    if (error == ENOENT) throw Error::NotFound("snapshot file " + path_);
    throw IoErrorFromErrno(path_, "open", error);
  }
  struct stat info;
  if (::fstat(fd_, &info) != 0) {
    int error = errno;
    ::close(fd_);
    throw IoErrorFromErrno(path_, "fstat", error);
  }
  if (!S_ISREG(info.st_mode)) {
    ::close(fd_);
    throw Error::BadInput(path_, "is not a regular file (it changed while it was opened), not a snapshot file");
  }
  size_ = static_cast<std::uint64_t>(info.st_size);
}

BinaryFile::~BinaryFile() {
  if (fd_ >= 0) ::close(fd_);
}

BinaryFile::BinaryFile(BinaryFile&& other) noexcept
    : path_(std::move(other.path_)), fd_(std::exchange(other.fd_, -1)), size_(other.size_) {}

BinaryFile& BinaryFile::operator=(BinaryFile&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    path_ = std::move(other.path_);
    fd_ = std::exchange(other.fd_, -1);
    size_ = other.size_;
  }
  return *this;
}

void BinaryFile::ReadAt(std::uint64_t offset, void* out, std::size_t length, std::string_view what) const {
  if (offset > size_ || length > size_ - offset) {
    throw Error::BadInput(path_, "truncated: " + std::string(what) + " needs bytes " +
                                     std::to_string(offset) + ".." + std::to_string(offset + length) +
                                     " but the file has " + std::to_string(size_) + " bytes");
  }
  auto* dest = static_cast<char*>(out);
  while (length > 0) {
    ssize_t got = ::pread(fd_, dest, length, static_cast<off_t>(offset));
    if (got < 0) {
      if (errno == EINTR) continue;
      throw IoErrorFromErrno(path_, "read of " + std::string(what), errno);
    }
    if (got == 0) {
      throw Error::BadInput(path_, "truncated: file shrank while reading " + std::string(what));
    }
    dest += got;
    offset += static_cast<std::uint64_t>(got);
    length -= static_cast<std::size_t>(got);
  }
}

void SwapByteOrder(void* data, std::size_t count, std::size_t width) {
  auto* bytes = static_cast<std::uint8_t*>(data);
  for (std::size_t i = 0; i < count; ++i) std::reverse(bytes + i * width, bytes + (i + 1) * width);
}

namespace {

template <typename Stored>
Stored LoadAs(const std::uint8_t* bytes, bool swap) {
  std::uint8_t copy[sizeof(Stored)];
  std::memcpy(copy, bytes, sizeof(Stored));
  if (swap) std::reverse(copy, copy + sizeof(Stored));
  Stored value;
  std::memcpy(&value, copy, sizeof(Stored));
  return value;
}

template <typename Stored, typename Out>
void DecodeAll(const std::uint8_t* bytes, std::size_t count, bool swap, Out* out) {
  for (std::size_t i = 0; i < count; ++i) out[i] = static_cast<Out>(LoadAs<Stored>(bytes + i * sizeof(Stored), swap));
}

template <typename Out>
void DecodeRealsAs(const std::uint8_t* bytes, std::size_t count, std::size_t width, bool swap, Out* out) {
  if (width == 4) {
    DecodeAll<float>(bytes, count, swap, out);
  } else {
    DecodeAll<double>(bytes, count, swap, out);
  }
}

}  // namespace

void DecodeReals(const std::uint8_t* bytes, std::size_t count, std::size_t width, bool swap, double* out) {
  DecodeRealsAs(bytes, count, width, swap, out);
}

void DecodeReals(const std::uint8_t* bytes, std::size_t count, std::size_t width, bool swap, float* out) {
  DecodeRealsAs(bytes, count, width, swap, out);
}

void DecodeUnsigned(const std::uint8_t* bytes, std::size_t count, std::size_t width, bool swap,
                    std::uint64_t* out) {
  if (width == 4) {
    DecodeAll<std::uint32_t>(bytes, count, swap, out);
  } else {
    DecodeAll<std::uint64_t>(bytes, count, swap, out);
  }
}

std::uint32_t LoadU32(const std::uint8_t* bytes, bool swap) { return LoadAs<std::uint32_t>(bytes, swap); }
double LoadF64(const std::uint8_t* bytes, bool swap) { return LoadAs<double>(bytes, swap); }

}  // namespace octocosm
