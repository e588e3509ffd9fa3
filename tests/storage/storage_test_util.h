// Helpers for the page-file and store tests: a scratch directory removed at
// the end of each test, deterministic random blocks, and byte-level surgery
// on files (flip, overwrite, truncate) for corruption tests.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "base/error.h"
#include "storage/block_source.h"

namespace octocosm::storagetest {

class ScratchDirectory {
 public:
  ScratchDirectory() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = std::string("octocosm-") + (info ? info->name() : "test") + "-" +
                       std::to_string(::getpid()) + "-" + std::to_string(counter_++);
    for (char& c : name) {
      if (c == '/') c = '_';
    }
    path_ = (std::filesystem::temp_directory_path() / name).string();
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~ScratchDirectory() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  ScratchDirectory(const ScratchDirectory&) = delete;
  ScratchDirectory& operator=(const ScratchDirectory&) = delete;

  const std::string& path() const { return path_; }
  std::string File(const std::string& name) const { return path_ + "/" + name; }

 private:
  static inline int counter_ = 0;
  std::string path_;
};

// Bytes that depend on (seed, key, size), so any reader can recompute them.
inline Bytes BlockContent(std::uint64_t seed, std::uint64_t key, std::size_t size) {
  std::mt19937_64 random(seed * 0x9e3779b97f4a7c15ull ^ key);
  Bytes bytes(size);
  for (std::size_t i = 0; i < size; i += 8) {
    std::uint64_t word = random();
    for (std::size_t j = 0; j < 8 && i + j < size; ++j) bytes[i + j] = static_cast<std::uint8_t>(word >> (8 * j));
  }
  return bytes;
}

inline std::uint64_t FileSize(const std::string& path) { return std::filesystem::file_size(path); }

inline std::uint8_t ReadByteAt(const std::string& path, std::uint64_t offset) {
  std::ifstream in(path, std::ios::binary);
  in.seekg(static_cast<std::streamoff>(offset));
  char c = 0;
  in.read(&c, 1);
  return static_cast<std::uint8_t>(c);
}

inline void WriteBytesAt(const std::string& path, std::uint64_t offset, const std::vector<std::uint8_t>& bytes) {
  std::fstream io(path, std::ios::binary | std::ios::in | std::ios::out);
  ASSERT_TRUE(io.good()) << path;
  io.seekp(static_cast<std::streamoff>(offset));
  io.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(io.good()) << path;
}

inline void FlipByte(const std::string& path, std::uint64_t offset, std::uint8_t mask = 0x01) {
  WriteBytesAt(path, offset, {static_cast<std::uint8_t>(ReadByteAt(path, offset) ^ mask)});
}

inline void TruncateFile(const std::string& path, std::uint64_t size) { std::filesystem::resize_file(path, size); }

inline std::vector<std::uint8_t> ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), {});
}

// Runs `action`, expects an octocosm::Error of `kind`, and returns its
// message (empty if none was thrown, after recording a failure).
inline std::string ExpectError(ErrorKind kind, const std::function<void()>& action) {
  try {
    action();
  } catch (const Error& error) {
    EXPECT_EQ(ErrorKindName(error.kind()), ErrorKindName(kind)) << error.what();
    return error.what();
  }
  ADD_FAILURE() << "expected an error of kind " << ErrorKindName(kind) << ", none was thrown";
  return {};
}

}  // namespace octocosm::storagetest
