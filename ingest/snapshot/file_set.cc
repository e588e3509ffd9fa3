#include "ingest/snapshot/file_set.h"

#include <sys/stat.h>

#include <cctype>
#include <cerrno>

#include "base/error.h"

namespace octocosm {
namespace {

bool IsRegularFile(const std::string& path) {
  struct stat info;
  return ::stat(path.c_str(), &info) == 0 && S_ISREG(info.st_mode);
}

bool Exists(const std::string& path) {
  struct stat info;
  return ::stat(path.c_str(), &info) == 0;
}

// What a non-regular file is, for messages.
std::string KindOfFile(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISFIFO(mode)) return "a FIFO (named pipe)";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

bool EndsWith(const std::string& text, const std::string& tail) {
  return text.size() >= tail.size() && text.compare(text.size() - tail.size(), tail.size(), tail) == 0;
}

}  // namespace

std::string NumberedName::WithIndex(std::size_t other) const {
  std::string digits = std::to_string(other);
  if (digits.size() < width) digits.insert(0, width - digits.size(), '0');
  return stem + "." + digits + suffix;
}

std::optional<NumberedName> ParseNumberedName(const std::string& path) {
  NumberedName name;
  std::string rest = path;
  for (const char* suffix : {".hdf5", ".h5"}) {
    if (EndsWith(rest, suffix)) {
      name.suffix = suffix;
      rest.resize(rest.size() - name.suffix.size());
      break;
    }
  }
  std::size_t dot = rest.rfind('.');
  if (dot == std::string::npos || dot + 1 == rest.size() || rest.find('/', dot) != std::string::npos) {
    return std::nullopt;
  }
  std::string digits = rest.substr(dot + 1);
  if (digits.size() > 9) return std::nullopt;
  for (char c : digits) {
    if (!std::isdigit(static_cast<unsigned char>(c))) return std::nullopt;
  }
  name.stem = rest.substr(0, dot);
  if (name.stem.empty() || name.stem.back() == '/') return std::nullopt;
  name.index = std::stoul(digits);
  name.width = digits.size() > 1 && digits[0] == '0' ? digits.size() : 1;
  return name;
}

void RequireRegularFile(const std::string& path) {
  struct stat info;
  if (::stat(path.c_str(), &info) != 0) {
    const int error = errno;
    if (error == ENOENT || error == ENOTDIR) throw Error::NotFound("snapshot file " + path);
    throw IoErrorFromErrno(path, "stat", error);
  }
  if (S_ISREG(info.st_mode)) return;
  throw Error::BadInput(path, "is " + KindOfFile(info.st_mode) + ", not a snapshot file");
}

std::string LocateSnapshotFile(const std::string& path) {
  if (IsRegularFile(path)) return path;
  std::string tried = path;
  for (const char* tail : {".0", ".0.hdf5", ".0.h5", ".hdf5"}) {
    std::string candidate = path + tail;
    if (IsRegularFile(candidate)) return candidate;
    tried += ", " + candidate;
  }
  // Something is there, but not a file: say what rather than "not found".
  if (Exists(path)) RequireRegularFile(path);
  throw Error::NotFound("snapshot " + path + " (tried " + tried + ")");
}

std::vector<std::string> ExpandFileSet(const std::string& file, long long declared) {
  std::optional<NumberedName> name = ParseNumberedName(file);
  if (declared == 1 || (declared <= 0 && !name)) return {file};
  if (!name) {
    throw Error::BadInput(file, "the header declares " + std::to_string(declared) +
                                    " files in this snapshot, but the file name has no .N number to find the others by");
  }
  std::vector<std::string> files;
  if (declared <= 0) {
    for (std::size_t i = 0; IsRegularFile(name->WithIndex(i)); ++i) files.push_back(name->WithIndex(i));
    if (files.empty() || name->index >= files.size()) return {file};
    return files;
  }
  if (name->index >= static_cast<std::size_t>(declared)) {
    throw Error::BadInput(file, "file number " + std::to_string(name->index) + " is outside the " +
                                    std::to_string(declared) + " files the header declares");
  }
  for (long long i = 0; i < declared; ++i) {
    std::string member = name->WithIndex(static_cast<std::size_t>(i));
    if (!IsRegularFile(member)) {
      if (Exists(member)) RequireRegularFile(member);
      throw Error::NotFound("file " + member + " of the " + std::to_string(declared) + "-file snapshot " + file);
    }
    files.push_back(member);
  }
  return files;
}

}  // namespace octocosm
