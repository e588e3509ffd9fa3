#include "base/error.h"

#include <cstring>

namespace octocosm {

std::string_view ErrorKindName(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::kIo: return "I/O error";
    case ErrorKind::kCorruption: return "corruption";
    case ErrorKind::kNotSupported: return "not supported";
    case ErrorKind::kInvalidArgument: return "invalid argument";
    case ErrorKind::kNotFound: return "not found";
    case ErrorKind::kBadInput: return "bad input";
  }
  return "error";
}

Error::Error(ErrorKind kind, const std::string& message)
    : std::runtime_error(message), kind_(kind) {}

Error Error::Io(const std::string& path, const std::string& what) {
  return Error(ErrorKind::kIo, path + ": I/O error: " + what);
}
Error Error::Corruption(const std::string& path, const std::string& what) {
  return Error(ErrorKind::kCorruption, path + ": corruption: " + what);
}
Error Error::NotSupported(const std::string& path, const std::string& what) {
  return Error(ErrorKind::kNotSupported, path + ": not supported: " + what);
}
Error Error::InvalidArgument(const std::string& what) {
  return Error(ErrorKind::kInvalidArgument, "invalid argument: " + what);
}
Error Error::NotFound(const std::string& what) {
  return Error(ErrorKind::kNotFound, "not found: " + what);
}
Error Error::BadInput(const std::string& path, const std::string& what) {
  return Error(ErrorKind::kBadInput, path + ": " + what);
}

Error IoErrorFromErrno(const std::string& path, const std::string& operation, int errno_value) {
  return Error::Io(path, operation + " failed: " + std::strerror(errno_value));
}

}  // namespace octocosm
