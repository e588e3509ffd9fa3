// A directory for temporary files, removed with everything in it when the
// object dies, whether the work that used it succeeded or threw.
#pragma once

#include <cerrno>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>

#include "storage/error.h"

namespace octocosm {

class TempDirectory {
 public:
  // Creates `parent`/`prefix`-XXXXXX.
  TempDirectory(const std::string& parent, const std::string& prefix) {
    std::string pattern = (std::filesystem::path(parent) / (prefix + "-XXXXXX")).string();
    if (::mkdtemp(pattern.data()) == nullptr) {
      throw IoErrorFromErrno(pattern, "creating the temporary directory", errno);
    }
    path_ = pattern;
  }
  ~TempDirectory() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  TempDirectory(const TempDirectory&) = delete;
  TempDirectory& operator=(const TempDirectory&) = delete;

  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

}  // namespace octocosm
