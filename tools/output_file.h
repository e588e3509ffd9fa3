// An output file of the command line (a query's points, trajectories, a
// picture) that appears whole or not at all: written under a temporary name
// in the same directory and renamed over the final name by Commit(). The
// temporary file is removed if Commit() is never reached (an error) and when
// SIGINT, SIGTERM or SIGHUP ends the program (base/interrupt_cleanup.h);
// an earlier file under the final name stays as it was until then.
//
// A path that exists and is not a regular file (a pipe, /dev/stdout, a
// terminal) is written directly: it cannot be replaced by a rename, and its
// reader sees the bytes as they come anyway. A symbolic link is followed, so
// that its target is replaced and the link stays.
#pragma once

#include <optional>
#include <string>

#include "base/interrupt_cleanup.h"

namespace octocosm {

class OutputFile {
 public:
  // Creates the temporary file, empty. Throws Error::Io naming `path`.
  explicit OutputFile(std::string path);
  ~OutputFile();
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  // Where to write: the temporary file, or the path itself (see above).
  const std::string& write_path() const { return write_path_; }
  // Call once the file is written and closed: renames it into place.
  void Commit();

 private:
  std::string path_;        // the final name, symbolic links resolved
  std::string write_path_;  // == path_ when written directly
  bool committed_ = false;
  std::optional<RemoveOnInterrupt> remove_on_interrupt_;
};

}  // namespace octocosm
