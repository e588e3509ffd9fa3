// A fresh scratch directory for a test, removed with everything in it when the
// object dies; a whole-file read for byte comparisons, and a value read from
// such bytes.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace octocosm::testing_support {

class TempDir {
 public:
  // `name` keeps directories of different tests apart; the process ID and a
  // counter keep parallel runs and repeated uses apart.
  explicit TempDir(const std::string& name) {
    path_ = std::filesystem::temp_directory_path() /
            ("octocosm-" + name + "-" + std::to_string(::getpid()) + "-" + std::to_string(counter_++));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }

 private:
  static inline int counter_ = 0;
  std::filesystem::path path_;
};

inline std::vector<std::uint8_t> ReadFileBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), {});
}

// The value of type T at `offset` of `bytes`, in the host's byte order (the
// test hosts are little endian, like the files the tests read).
template <typename T>
T LoadHostOrder(const std::vector<std::uint8_t>& bytes, std::size_t offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof value);
  return value;
}

}  // namespace octocosm::testing_support
