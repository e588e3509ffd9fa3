#include "tools/output_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <random>
#include <system_error>

#include "base/error.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

// Creates an empty file named after `path` (hidden, with a random suffix)
// in its directory, with the permissions a new file there gets (0666 less
// the umask, as open(2) gives); returns its name.
std::string CreateTemporaryBeside(const fs::path& path) {
  const fs::path directory = path.has_parent_path() ? path.parent_path() : fs::path(".");
  std::random_device device;
  constexpr char kLetters[] = "abcdefghijklmnopqrstuvwxyz0123456789";
  for (int attempt = 0; attempt < 100; ++attempt) {
    std::string suffix(6, ' ');
    for (char& c : suffix) c = kLetters[device() % (sizeof kLetters - 1)];
    const std::string name = (directory / ("." + path.filename().string() + ".octocosm-" + suffix)).string();
    const int fd = ::open(name.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd >= 0) {
      ::close(fd);
      return name;
    }
    if (errno != EEXIST) {
      throw IoErrorFromErrno(path.string(), "creating a temporary file beside it (" + name + ")", errno);
    }
  }
  throw Error::Io(path.string(), "no free temporary name beside it after 100 tries");
}

}  // namespace

OutputFile::OutputFile(std::string path) : path_(std::move(path)) {
  std::error_code error;
  if (fs::is_symlink(path_, error)) {
    const fs::path target = fs::weakly_canonical(path_, error);
    if (error) throw Error::Io(path_, "following the symbolic link: " + error.message());
    path_ = target.string();
  }
  const fs::file_status status = fs::status(path_, error);
  if (fs::exists(status) && !fs::is_regular_file(status)) {
    if (fs::is_directory(status)) throw Error::InvalidArgument(path_ + " is a directory, not a file to write");
    write_path_ = path_;
    return;
  }
  write_path_ = CreateTemporaryBeside(path_);
  remove_on_interrupt_.emplace([temporary = write_path_] { std::remove(temporary.c_str()); });
}

OutputFile::~OutputFile() {
  if (!committed_ && write_path_ != path_) std::remove(write_path_.c_str());
}

void OutputFile::Commit() {
  if (committed_) return;
  if (write_path_ != path_ && std::rename(write_path_.c_str(), path_.c_str()) != 0) {
    const int error = errno;
    std::remove(write_path_.c_str());
    committed_ = true;
    throw IoErrorFromErrno(path_, "renaming the finished file into place", error);
  }
  committed_ = true;
  remove_on_interrupt_.reset();
}

}  // namespace octocosm
