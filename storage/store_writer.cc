#include "storage/store_writer.h"

#include <fcntl.h>
#include <stdio.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <random>

#include "base/error.h"
#include "storage/file.h"
#include "storage/page_file_reader.h"

namespace octocosm {
namespace {

std::uint64_t RandomStoreId() {
  std::random_device device;
  std::uint64_t id = 0;
  while (id == 0) id = (std::uint64_t{device()} << 32) ^ device();
  return id;
}

bool IsStoreFileName(const std::string& name) {
  return name.rfind(kManifestFileName, 0) == 0 || name.rfind("epoch-", 0) == 0;
}

// The lock file, and the file it is made under before it is renamed into
// place.
bool IsWriterLockFileName(const std::string& name) { return name.rfind(kWriterLockFileName, 0) == 0; }

// A directory holding writer files and nothing else: a nested store.
bool HoldsOnlyStoreFiles(const std::string& directory) {
  const std::vector<std::string> names = ListDirectory(directory);
  if (names.empty()) return false;  // nothing says it is ours
  for (const std::string& name : names) {
    if (!IsStoreFileName(name) && !IsWriterLockFileName(name)) return false;
    if (IsDirectory(JoinPath(directory, name))) return false;
  }
  return true;
}

// "pid 1234", as the writer wrote it into its lock file; "" if unreadable.
std::string LockOwner(int fd) {
  char text[64] = {};
  const ssize_t got = ::pread(fd, text, sizeof text - 1, 0);
  std::string owner(text, got > 0 ? static_cast<std::size_t>(got) : 0);
  while (!owner.empty() && (owner.back() == '\n' || owner.back() == ' ')) owner.pop_back();
  return owner;
}

}  // namespace

void RemoveUnfinishedStore(const std::string& directory) noexcept {
  try {
    if (PathExists(JoinPath(directory, kManifestFileName))) return;
    std::vector<std::string> locks;
    for (const std::string& name : ListDirectory(directory)) {
      const std::string path = JoinPath(directory, name);
      if (IsDirectory(path)) {
        if (!HoldsOnlyStoreFiles(path)) continue;
        for (const std::string& inner : ListDirectory(path)) RemoveFileQuietly(JoinPath(path, inner));
        ::rmdir(path.c_str());
      } else if (IsWriterLockFileName(name)) {
        locks.push_back(path);
      } else if (IsStoreFileName(name)) {
        RemoveFileQuietly(path);
      }
    }
    // Last, so that whatever remains after a failure still reads as abandoned.
    for (const std::string& path : locks) RemoveFileQuietly(path);
  } catch (...) {
    // Best effort: a later writer finds whatever remains.
  }
}

StoreWriter::StoreWriter(std::string directory, nlohmann::json dataset, nlohmann::json attribute_schema,
                         StoreWriterOptions options)
    : directory_(std::move(directory)) {
  if (!IsValidPageSize(options.page_size)) {
    throw Error::InvalidArgument("page size " + std::to_string(options.page_size) +
                                 " is not a power of two in [4096, 16777216]");
  }
  if (!dataset.is_object()) throw Error::InvalidArgument("store dataset metadata must be a JSON object");
  created_directory_ = !IsDirectory(directory_);
  CreateDirectories(directory_);
  RemoveAbandonedWrite();
  // Never write over another store, finished or not: its manifest would
  // otherwise describe files this writer is replacing. Files without the
  // lock file may be anyone's: not this writer's to remove.
  for (const std::string& name : ListDirectory(directory_)) {
    if (IsStoreFileName(name)) {
      throw Error::InvalidArgument(directory_ + " already holds store file " + name +
                                   "; remove the old store (or its leftovers) first");
    }
  }
  LockDirectory();
  manifest_.store_id = options.store_id != 0 ? options.store_id : RandomStoreId();
  first_epoch_ = options.first_epoch;
  manifest_.page_size = options.page_size;
  manifest_.dataset = std::move(dataset);
  manifest_.attribute_schema = std::move(attribute_schema);
}

StoreWriter::~StoreWriter() {
  if (finished_) return;
  RemoveCreatedFiles();
  UnlockDirectory();
  if (created_directory_) ::rmdir(directory_.c_str());  // only if nothing else is in it
}

void StoreWriter::RemoveAbandonedWrite() {
  const std::string lock_path = JoinPath(directory_, kWriterLockFileName);
  // A writer killed while it made its lock file leaves that file under the
  // name it was made under (LockDirectory); a live one holds it locked.
  const std::string unlocked_prefix = std::string(kWriterLockFileName) + ".";
  for (const std::string& name : ListDirectory(directory_)) {
    if (name.rfind(unlocked_prefix, 0) != 0) continue;
    const std::string path = JoinPath(directory_, name);
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) continue;
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) RemoveFileQuietly(path);
    ::close(fd);
  }
  for (;;) {
    const int fd = ::open(lock_path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
      if (errno == ENOENT) return;
      throw IoErrorFromErrno(lock_path, "opening the lock file of an earlier store writer", errno);
    }
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int error = errno;
      const std::string owner = LockOwner(fd);
      ::close(fd);
      if (error == EWOULDBLOCK) {
        throw Error::InvalidArgument(directory_ + " is being written by another process" +
                                     (owner.empty() ? std::string() : " (" + owner + ")") +
                                     "; wait for it to finish, or stop it first");
      }
      throw IoErrorFromErrno(lock_path, "locking the lock file of an earlier store writer", error);
    }
    // Between the open and the lock another writer may have cleared this
    // lock file away and made its own: then look again.
    struct stat held {}, current {};
    if (::fstat(fd, &held) != 0 || ::stat(lock_path.c_str(), &current) != 0 || held.st_ino != current.st_ino ||
        held.st_dev != current.st_dev) {
      ::close(fd);
      continue;
    }
    // Its writer is dead. A finished store (killed after the commit, before
    // the lock file went) keeps everything but that file.
    if (PathExists(JoinPath(directory_, kManifestFileName))) {
      RemoveFileQuietly(lock_path);
    } else {
      RemoveUnfinishedStore(directory_);
    }
    ::close(fd);
    return;
  }
}

void StoreWriter::LockDirectory() {
  const std::string lock_path = JoinPath(directory_, kWriterLockFileName);
  // Made and locked under another name, then linked into place: whoever
  // finds the lock file finds it locked while its writer lives, and link
  // fails, rather than replaces, if another writer got there first.
  std::string unlocked_path = lock_path + ".XXXXXX";
  const int fd = ::mkostemp(unlocked_path.data(), O_CLOEXEC);
  if (fd < 0) throw IoErrorFromErrno(unlocked_path, "creating the store writer's lock file", errno);
  const std::string owner = "pid " + std::to_string(::getpid()) + "\n";
  int error = 0;
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0 ||
      ::write(fd, owner.data(), owner.size()) != static_cast<ssize_t>(owner.size())) {
    error = errno;
  } else if (::link(unlocked_path.c_str(), lock_path.c_str()) != 0) {
    error = errno;
    // File systems without hard links: a rename that refuses to replace.
    if ((error == EPERM || error == EOPNOTSUPP) &&
        ::renameat2(AT_FDCWD, unlocked_path.c_str(), AT_FDCWD, lock_path.c_str(), RENAME_NOREPLACE) == 0) {
      error = 0;
    }
  }
  ::unlink(unlocked_path.c_str());
  if (error != 0) {
    ::close(fd);
    if (error == EEXIST) {
      throw Error::InvalidArgument(directory_ + " is being written by another process (its " + kWriterLockFileName +
                                   " appeared just now)");
    }
    throw IoErrorFromErrno(lock_path, "creating the store writer's lock file", error);
  }
  lock_fd_ = fd;
}

void StoreWriter::UnlockDirectory() noexcept {
  if (lock_fd_ < 0) return;
  // Removed before it is unlocked, so that nobody takes a lock file that is
  // about to go for an abandoned one.
  RemoveFileQuietly(JoinPath(directory_, kWriterLockFileName));
  ::close(lock_fd_);
  lock_fd_ = -1;
}

void StoreWriter::RemoveCreatedFiles() noexcept {
  epoch_writer_.reset();  // removes its .tmp file
  for (const std::string& path : created_files_) RemoveFileQuietly(path);
  RemoveFileQuietly(JoinPath(directory_, std::string(kManifestFileName) + kTemporarySuffix));
  created_files_.clear();
}

void StoreWriter::RequireUnfinished(const char* operation) const {
  if (finished_) throw Error::InvalidArgument(std::string(operation) + " after Finish() on store " + directory_);
}

std::uint32_t StoreWriter::BeginEpoch(double time, double redshift) {
  RequireUnfinished("BeginEpoch");
  if (open_epoch_) {
    throw Error::InvalidArgument("BeginEpoch while epoch " + std::to_string(open_epoch_->epoch) + " of " +
                                 directory_ + " is open; call EndEpoch first");
  }
  if (!std::isfinite(time) || !std::isfinite(redshift)) {
    throw Error::InvalidArgument("epoch time and redshift must be finite numbers");
  }
  EpochInfo info;
  info.epoch = first_epoch_ + static_cast<std::uint32_t>(manifest_.epochs.size());
  info.file = EpochFileName(info.epoch);
  info.time = time;
  info.redshift = redshift;
  epoch_writer_.emplace(JoinPath(directory_, info.file), manifest_.page_size, manifest_.store_id, info.epoch);
  open_epoch_ = info;
  return info.epoch;
}

void StoreWriter::AddBlock(std::uint64_t key, std::span<const std::uint8_t> bytes, std::uint64_t point_count) {
  if (!epoch_writer_) throw Error::InvalidArgument("AddBlock with no open epoch in " + directory_);
  epoch_writer_->AddBlock(key, bytes, point_count);
}

std::uint64_t StoreWriter::ReserveBlocksOf(const PageFileReader& source) {
  if (!epoch_writer_) throw Error::InvalidArgument("ReserveBlocksOf with no open epoch in " + directory_);
  return epoch_writer_->ReserveBlocksOf(source);
}

std::string StoreWriter::open_epoch_temporary_path() const {
  if (!epoch_writer_) throw Error::InvalidArgument("no open epoch in " + directory_);
  return epoch_writer_->temporary_path();
}

void StoreWriter::EndEpoch() {
  if (!epoch_writer_) throw Error::InvalidArgument("EndEpoch with no open epoch in " + directory_);
  PageFileWriter::Summary summary = epoch_writer_->Finish();
  created_files_.push_back(epoch_writer_->path());
  epoch_writer_.reset();
  EpochInfo info = *open_epoch_;
  open_epoch_.reset();
  info.block_count = summary.block_count;
  info.file_size = summary.file_size;
  finished_bytes_ += summary.file_size;
  manifest_.epochs.push_back(std::move(info));
}

void StoreWriter::SetDataset(nlohmann::json dataset) {
  RequireUnfinished("SetDataset");
  if (!dataset.is_object()) throw Error::InvalidArgument("store dataset metadata must be a JSON object");
  manifest_.dataset = std::move(dataset);
}

void StoreWriter::Finish() {
  RequireUnfinished("Finish");
  if (first_epoch_ != 0) {
    throw Error::InvalidArgument("Finish on " + directory_ + ", a part of a store from epoch " +
                                 std::to_string(first_epoch_) + "; call FinishPart");
  }
  if (open_epoch_) {
    throw Error::InvalidArgument("Finish while epoch " + std::to_string(open_epoch_->epoch) + " of " +
                                 directory_ + " is open; call EndEpoch first");
  }
  // The manifest is the commit record: written under a temporary name,
  // made durable, then renamed, so that it exists only complete.
  const std::string final_path = JoinPath(directory_, kManifestFileName);
  const std::string temporary_path = final_path + kTemporarySuffix;
  std::string text = manifest_.ToJson().dump(2) + "\n";
  WritableFile file = WritableFile::Create(temporary_path);
  file.Append(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
  file.Sync();
  file.Close();
  RenameFile(temporary_path, final_path);
  // Until the directory is synced the commit is not durable; if that fails,
  // the destructor removes the manifest with everything else.
  created_files_.push_back(final_path);
  SyncDirectory(directory_);
  finished_bytes_ += text.size();
  finished_ = true;
  UnlockDirectory();
}

std::vector<EpochInfo> StoreWriter::FinishPart() {
  RequireUnfinished("FinishPart");
  if (open_epoch_) {
    throw Error::InvalidArgument("FinishPart while epoch " + std::to_string(open_epoch_->epoch) + " of " +
                                 directory_ + " is open; call EndEpoch first");
  }
  SyncDirectory(directory_);
  finished_ = true;
  UnlockDirectory();
  return manifest_.epochs;
}

void StoreWriter::AdoptEpochs(const std::string& part_directory, const std::vector<EpochInfo>& epochs) {
  RequireUnfinished("AdoptEpochs");
  if (open_epoch_) {
    throw Error::InvalidArgument("AdoptEpochs while epoch " + std::to_string(open_epoch_->epoch) + " of " +
                                 directory_ + " is open; call EndEpoch first");
  }
  for (const EpochInfo& epoch : epochs) {
    const std::uint32_t expected = first_epoch_ + static_cast<std::uint32_t>(manifest_.epochs.size());
    const std::string from = JoinPath(part_directory, epoch.file);
    if (epoch.epoch != expected || epoch.file != EpochFileName(epoch.epoch)) {
      throw Error::InvalidArgument("adopting " + from + " as epoch " + std::to_string(epoch.epoch) + " of " +
                                   directory_ + ", whose next epoch is " + std::to_string(expected));
    }
    {
      const std::unique_ptr<PageFileReader> reader = PageFileReader::Open(from);
      const PageFileHeader& header = reader->header();
      if (header.store_id != manifest_.store_id || header.epoch != epoch.epoch ||
          header.page_size != manifest_.page_size || reader->block_count() != epoch.block_count ||
          header.file_size() != epoch.file_size) {
        throw Error::InvalidArgument("adopting " + from + " into " + directory_ +
                                     ": its header or size is not that of the part's epoch " +
                                     std::to_string(epoch.epoch) + " of this store");
      }
    }
    const std::string to = JoinPath(directory_, epoch.file);
    RenameFile(from, to);
    created_files_.push_back(to);
    finished_bytes_ += epoch.file_size;
    manifest_.epochs.push_back(epoch);
  }
  SyncDirectory(directory_);
}

std::uint64_t StoreWriter::bytes_written() const {
  return finished_bytes_ + (epoch_writer_ ? epoch_writer_->bytes_written() : 0);
}

}  // namespace octocosm
