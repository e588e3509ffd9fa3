// A directory for temporary files, removed with everything in it when the
// object dies, whether the work that used it succeeded or threw, and when
// SIGINT, SIGTERM or SIGHUP ends the program (base/interrupt_cleanup.h).
//
// A process killed outright (kill -9, a crash, the OOM killer) removes
// nothing. So each directory holds a lock file that its owner keeps locked
// (flock, released by the kernel when the owner dies, however it dies), and
// creating a directory first removes the abandoned ones beside it: those of
// the same prefix whose lock no process holds.
#pragma once

#include <optional>
#include <string>

#include "base/interrupt_cleanup.h"

namespace octocosm {

class TempDirectory {
 public:
  // Creates `parent`/`prefix`-XXXXXX (and `parent` if missing), after
  // removing abandoned `parent`/`prefix`-XXXXXX directories.
  TempDirectory(const std::string& parent, const std::string& prefix);
  ~TempDirectory();
  TempDirectory(const TempDirectory&) = delete;
  TempDirectory& operator=(const TempDirectory&) = delete;

  const std::string& path() const { return path_; }

  // The name of the lock file inside each directory.
  static constexpr const char* kLockFileName = "owner.lock";
  // Removes `parent`/`prefix`-XXXXXX directories whose lock file exists and
  // is held by no process; returns how many. A directory without a lock file
  // is left alone: it may be one whose owner is still creating it.
  static int RemoveAbandoned(const std::string& parent, const std::string& prefix);

 private:
  std::string path_;
  int lock_fd_ = -1;
  std::optional<RemoveOnInterrupt> remove_on_interrupt_;
};

}  // namespace octocosm
