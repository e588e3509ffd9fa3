// The one error type of octocosm.
//
// Every failure that a caller may want to tell apart has its own kind:
// corruption (the bytes on disk are not what was written) is reported apart
// from I/O failure (the OS refused), so that a user knows whether to replace a
// disk or re-run an ingest. The message always names the file and, where there
// is one, the block, and says what was expected. Deep code never exits; it
// throws, and only the command-line front end turns an Error into a status.
#pragma once

#include <stdexcept>
#include <string>
#include <string_view>

namespace octocosm {

enum class ErrorKind {
  kIo,               // the operating system failed a call (open, read, write, fsync, rename)
  kCorruption,       // stored bytes fail a checksum or a structural check
  kNotSupported,     // a valid file of a format version or feature this build cannot read
  kInvalidArgument,  // the caller asked for something impossible (bad flag, bad key)
  kNotFound,         // a key, file or dataset that is not there
  kBadInput,         // an input file (snapshot, CSV) that is malformed
};

std::string_view ErrorKindName(ErrorKind kind);

class Error : public std::runtime_error {
 public:
  Error(ErrorKind kind, const std::string& message);

  ErrorKind kind() const { return kind_; }

  static Error Io(const std::string& path, const std::string& what);
  static Error Corruption(const std::string& path, const std::string& what);
  static Error NotSupported(const std::string& path, const std::string& what);
  static Error InvalidArgument(const std::string& what);
  static Error NotFound(const std::string& what);
  static Error BadInput(const std::string& path, const std::string& what);

 private:
  ErrorKind kind_;
};

// Io error for a failed system call: appends strerror(errno_value).
Error IoErrorFromErrno(const std::string& path, const std::string& operation, int errno_value);

}  // namespace octocosm
