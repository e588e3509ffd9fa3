#include "base/temp_directory.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <filesystem>
#include <system_error>

#include "base/error.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

// mkdtemp's six random characters.
constexpr std::size_t kRandomSuffixLength = 6;

bool HasTempDirectoryName(const std::string& name, const std::string& prefix) {
  return name.size() == prefix.size() + 1 + kRandomSuffixLength && name.compare(0, prefix.size(), prefix) == 0 &&
         name[prefix.size()] == '-';
}

// Locks `directory`/kLockFileName for the caller's lifetime. The file is
// created and locked under another name and then renamed into place, so
// that whoever finds the lock file finds it locked while its owner lives.
int CreateLockFile(const std::string& directory) {
  const std::string lock_path = (fs::path(directory) / TempDirectory::kLockFileName).string();
  const std::string unlocked_path = lock_path + ".new";
  const int fd = ::open(unlocked_path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) throw IoErrorFromErrno(unlocked_path, "creating the temporary directory's lock file", errno);
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0 || ::rename(unlocked_path.c_str(), lock_path.c_str()) != 0) {
    const int error = errno;
    ::close(fd);
    throw IoErrorFromErrno(lock_path, "locking the temporary directory", error);
  }
  return fd;
}

}  // namespace

int TempDirectory::RemoveAbandoned(const std::string& parent, const std::string& prefix) {
  int removed = 0;
  std::error_code error;
  for (fs::directory_iterator it(parent, error), end; !error && it != end; it.increment(error)) {
    const std::string name = it->path().filename().string();
    if (!HasTempDirectoryName(name, prefix) || !it->is_directory(error)) continue;
    const std::string lock_path = (it->path() / kLockFileName).string();
    const int fd = ::open(lock_path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) continue;
    // Holding the lock while removing: a second run sweeping at the same
    // moment finds it locked and leaves the directory to this one.
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
      std::error_code ignored;
      fs::remove_all(it->path(), ignored);
      ++removed;
    }
    ::close(fd);
  }
  return removed;
}

TempDirectory::TempDirectory(const std::string& parent, const std::string& prefix) {
  std::error_code error;
  fs::create_directories(parent, error);
  if (error) throw Error::Io(parent, "creating the directory for temporary files: " + error.message());
  RemoveAbandoned(parent, prefix);
  std::string pattern = (fs::path(parent) / (prefix + "-" + std::string(kRandomSuffixLength, 'X'))).string();
  if (::mkdtemp(pattern.data()) == nullptr) {
    throw IoErrorFromErrno(pattern, "creating the temporary directory", errno);
  }
  path_ = pattern;
  const std::string path = path_;
  remove_on_interrupt_.emplace([path] {
    std::error_code ignored;
    fs::remove_all(path, ignored);
  });
  try {
    lock_fd_ = CreateLockFile(path_);
  } catch (...) {
    fs::remove_all(path_, error);
    throw;
  }
}

TempDirectory::~TempDirectory() {
  std::error_code ignored;
  fs::remove_all(path_, ignored);
  ::close(lock_fd_);  // after the removal: until then the directory is visibly in use
}

}  // namespace octocosm
