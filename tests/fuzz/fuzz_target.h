// What every fuzz target in tests/fuzz shares.
//
// A target is the libFuzzer entry point LLVMFuzzerTestOneInput: it hands the
// bytes to one reader and runs the reader to completion. An octocosm Error
// is the reader refusing bad input, the outcome expected of most inputs;
// anything else (a crash, a sanitizer report, any other exception, which
// std::terminate turns into an abort) is a finding. std::bad_alloc is one
// too: a reader must bound what it allocates by checks of its own.
//
// Each target also supplies Seeds(): small valid inputs made in code, plus
// the real snapshots of the shared data folder where it exists. Our own
// mutation driver (fuzz_driver.cc) mutates them in the gcc builds; in the
// libFuzzer build that driver writes them out as the starting corpus.
#pragma once

#include <unistd.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <vector>

#include "base/error.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace octocosm::fuzz {

struct Seed {
  std::string name;  // a file name for the corpus
  std::string bytes;
};

// The target's seeds. `shared_data` is the shared data folder, or empty to
// leave real snapshots out.
std::vector<Seed> Seeds(const std::string& shared_data);

// A reader refused its input: the expected outcome. With
// OCTOCOSM_FUZZ_PRINT_ERRORS set in the environment, prints the message, to
// see how far inputs get.
// The count of refusals lets the driver check that every seed made in code
// is read without one: a seed the readers came to refuse would leave the
// short run testing only the first check.
inline std::size_t& RefusalCount() {
  static std::size_t count = 0;
  return count;
}

inline void Refused(const Error& error) {
  static const bool print = std::getenv("OCTOCOSM_FUZZ_PRINT_ERRORS") != nullptr;
  if (print) std::fprintf(stderr, "refused: %s\n", error.what());
  ++RefusalCount();
}

// A broken invariant of a reader that did not throw: a finding like a crash.
inline void Require(bool condition, const char* what) {
  if (!condition) {
    std::fprintf(stderr, "fuzz target: %s\n", what);
    std::abort();
  }
}

// A per-process scratch directory for the files a reader must be given by
// path; removed at exit. Every call returns the same directory.
inline const std::filesystem::path& ScratchDirectory() {
  struct Directory {
    std::filesystem::path path;
    Directory() {
      path = std::filesystem::temp_directory_path() / ("octocosm-fuzz-" + std::to_string(::getpid()));
      std::filesystem::remove_all(path);
      std::filesystem::create_directories(path);
    }
    ~Directory() {
      std::error_code ignored;
      std::filesystem::remove_all(path, ignored);
    }
  };
  static const Directory directory;
  return directory.path;
}

inline void WriteFileBytes(const std::filesystem::path& path, std::span<const std::uint8_t> bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

inline std::string ReadFileString(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// The regular files of `folder` (a subfolder of `shared_data`) whose names
// pass `keep`, sorted by name, as seeds; none when `shared_data` is empty or
// lacks the folder.
template <typename Keep>
std::vector<Seed> SharedDataSeeds(const std::string& shared_data, const std::string& folder, Keep keep) {
  std::vector<Seed> seeds;
  if (shared_data.empty()) return seeds;
  const std::filesystem::path dir = std::filesystem::path(shared_data) / folder;
  if (!std::filesystem::is_directory(dir)) return seeds;
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.is_regular_file() && keep(entry.path().filename().string())) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  for (const auto& file : files) seeds.push_back({folder + "-" + file.filename().string(), ReadFileString(file)});
  return seeds;
}

}  // namespace octocosm::fuzz
