// A read-only file read at explicit offsets, and the byte decoding the binary
// readers share. Reading past the end is reported as a truncated input
// (Error::BadInput naming the file and what was being read), not as an I/O
// error, because for a snapshot it means the file is incomplete.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace octocosm {

class BinaryFile {
 public:
  // Throws Error::NotFound when the file does not exist, Error::BadInput when
  // it is not a regular file (RequireRegularFile), Error::Io otherwise.
  explicit BinaryFile(std::string path);
  ~BinaryFile();
  BinaryFile(BinaryFile&& other) noexcept;
  BinaryFile& operator=(BinaryFile&& other) noexcept;
  BinaryFile(const BinaryFile&) = delete;
  BinaryFile& operator=(const BinaryFile&) = delete;

  const std::string& path() const { return path_; }
  std::uint64_t size() const { return size_; }

  // Reads exactly `length` bytes at `offset` into `out`. `what` names the data
  // for the error message when the file ends too early.
  void ReadAt(std::uint64_t offset, void* out, std::size_t length, std::string_view what) const;

 private:
  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
};

// Reverses the byte order of `count` values of `width` bytes each, in place.
void SwapByteOrder(void* data, std::size_t count, std::size_t width);

// Decodes `count` values of a `width`-byte IEEE float (4 or 8) stored in
// `bytes`, swapping byte order first when `swap` is set.
void DecodeReals(const std::uint8_t* bytes, std::size_t count, std::size_t width, bool swap, double* out);
void DecodeReals(const std::uint8_t* bytes, std::size_t count, std::size_t width, bool swap, float* out);
// Same for unsigned integers of 4 or 8 bytes.
void DecodeUnsigned(const std::uint8_t* bytes, std::size_t count, std::size_t width, bool swap,
                    std::uint64_t* out);

// Loads one 4-byte little- or big-endian integer or 8-byte float (`swap` =
// differs from host).
std::uint32_t LoadU32(const std::uint8_t* bytes, bool swap);
double LoadF64(const std::uint8_t* bytes, bool swap);

}  // namespace octocosm
