#include "storage/range_cache.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <vector>

#include "base/error.h"
#include "storage/checksum.h"
#include "storage/coding.h"
#include "storage/file.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

constexpr std::size_t kTrailerBytes = 8;  // the checksum after the bytes
constexpr const char* kTemporaryMarker = ".partial-";

std::uint64_t KeyHash(const std::string& file_key) {
  return Checksum64(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(file_key.data()),
                                                  file_key.size()));
}

// What the trailer checksums besides the bytes: which file and where, so an
// entry renamed or copied to another name does not pass for that one.
std::array<std::uint8_t, 24> EntryIdentity(std::uint64_t key_hash, std::uint64_t offset, std::uint64_t length) {
  std::array<std::uint8_t, 24> identity{};
  PutU64(identity.data(), key_hash);
  PutU64(identity.data() + 8, offset);
  PutU64(identity.data() + 16, length);
  return identity;
}

struct EntryFile {
  fs::file_time_type used;
  std::uint64_t size = 0;
  fs::path path;
};

// Every file under the cache directory (entries and temporaries), and their total size.
std::vector<EntryFile> ListEntries(const std::string& directory, std::uint64_t& total) {
  std::vector<EntryFile> entries;
  total = 0;
  std::error_code error;
  for (fs::recursive_directory_iterator it(directory, error), end; !error && it != end; it.increment(error)) {
    std::error_code ignored;
    if (!it->is_regular_file(ignored)) continue;
    EntryFile entry{it->last_write_time(ignored), it->file_size(ignored), it->path()};
    total += entry.size;
    entries.push_back(std::move(entry));
  }
  return entries;
}

}  // namespace

std::shared_ptr<RangeCache> RangeCache::Open(const std::string& directory, std::uint64_t budget_bytes) {
  CreateDirectories(directory);
  std::shared_ptr<RangeCache> cache(new RangeCache(directory, budget_bytes));
  std::uint64_t total = 0;
  ListEntries(directory, total);
  cache->bytes_ = total;
  if (total > budget_bytes) cache->Evict();
  return cache;
}

RangeCache::RangeCache(std::string directory, std::uint64_t budget_bytes)
    : directory_(std::move(directory)), budget_bytes_(budget_bytes) {}

std::string RangeCache::EntryPath(const std::string& file_key, std::uint64_t offset, std::uint64_t length) const {
  const std::uint64_t key_hash = KeyHash(file_key);
  const auto identity = EntryIdentity(key_hash, offset, length);
  // Entries spread over 256 subdirectories, so no directory grows huge.
  const std::string spread = Hex64(Checksum64(identity)).substr(0, 2);
  return JoinPath(JoinPath(directory_, spread),
                  Hex64(key_hash) + "-" + std::to_string(offset) + "-" + std::to_string(length));
}

bool RangeCache::Get(const std::string& file_key, std::uint64_t offset, std::span<std::uint8_t> out) {
  const std::string path = EntryPath(file_key, offset, out.size());
  try {
    const RandomAccessFile file = RandomAccessFile::Open(path);
    std::array<std::uint8_t, kTrailerBytes> trailer{};
    const bool whole = file.Size() == out.size() + kTrailerBytes && file.ReadAt(0, out) == out.size() &&
                       file.ReadAt(out.size(), trailer) == kTrailerBytes;
    const auto identity = EntryIdentity(KeyHash(file_key), offset, out.size());
    if (!whole || GetU64(trailer.data()) != Checksum64(identity, out)) {
      damaged_.fetch_add(1, std::memory_order_relaxed);
      RemoveFileQuietly(path);
      misses_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
  } catch (const Error&) {
    misses_.fetch_add(1, std::memory_order_relaxed);  // not cached (or unreadable: fetched instead)
    return false;
  }
  ::utimensat(AT_FDCWD, path.c_str(), nullptr, 0);  // recently used: evicted last
  hits_.fetch_add(1, std::memory_order_relaxed);
  return true;
}

void RangeCache::Put(const std::string& file_key, std::uint64_t offset, std::span<const std::uint8_t> bytes) {
  if (bytes.size() + kTrailerBytes > budget_bytes_) return;
  const std::string path = EntryPath(file_key, offset, bytes.size());
  const std::string temporary = path + kTemporaryMarker + std::to_string(::getpid()) + "-" +
                                std::to_string(temporary_counter_.fetch_add(1));
  try {
    CreateDirectories(fs::path(path).parent_path().string());
    std::array<std::uint8_t, kTrailerBytes> trailer{};
    PutU64(trailer.data(), Checksum64(EntryIdentity(KeyHash(file_key), offset, bytes.size()), bytes));
    WritableFile file = WritableFile::Create(temporary);
    file.Append(bytes);
    file.Append(trailer);
    file.Close();
    RenameFile(temporary, path);
  } catch (const Error&) {
    RemoveFileQuietly(temporary);
    return;
  }
  if (bytes_.fetch_add(bytes.size() + kTrailerBytes) + bytes.size() + kTrailerBytes > budget_bytes_) Evict();
}

void RangeCache::Evict() {
  std::lock_guard<std::mutex> lock(evict_mutex_);
  std::uint64_t total = 0;
  std::vector<EntryFile> entries = ListEntries(directory_, total);
  const std::uint64_t target = budget_bytes_ / 10 * 9;
  if (total > target) {
    std::sort(entries.begin(), entries.end(), [](const EntryFile& a, const EntryFile& b) { return a.used < b.used; });
    for (const EntryFile& entry : entries) {
      if (total <= target) break;
      std::error_code ignored;
      if (fs::remove(entry.path, ignored)) {
        total -= entry.size;
        evicted_.fetch_add(1, std::memory_order_relaxed);
      }
    }
  }
  bytes_ = total;
}

RangeCacheStats RangeCache::stats() const {
  return RangeCacheStats{hits_.load(), misses_.load(), damaged_.load(), evicted_.load(), bytes_.load()};
}

}  // namespace octocosm
