// A directory of byte ranges fetched from remote files, kept between runs
// and between processes within a byte budget, least recently used out first.
//
// A range is filed under its file's key (URL, size and validator: a file
// changed on the server has a new key, so a stale copy is never found) and
// its offset and length. Each entry carries a checksum of its key and bytes:
// a damaged or truncated entry is removed and reported as missing, so the
// caller fetches the range again. Entries are written under a temporary name
// and renamed into place, so concurrent readers see whole entries or none.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>

namespace octocosm {

struct RangeCacheStats {
  std::uint64_t hits = 0;
  std::uint64_t misses = 0;
  std::uint64_t damaged = 0;   // entries found damaged and removed
  std::uint64_t evicted = 0;   // entries removed to keep to the budget
  std::uint64_t bytes = 0;     // held now, as this process counts them
};

class RangeCache {
 public:
  // Creates `directory` if needed and counts what it holds. kIo if it cannot.
  static std::shared_ptr<RangeCache> Open(const std::string& directory, std::uint64_t budget_bytes);

  // Fills `out` with the cached bytes [offset, offset + out.size()) of the
  // file `file_key`; false when they are not cached (or were damaged).
  bool Get(const std::string& file_key, std::uint64_t offset, std::span<std::uint8_t> out);
  // Files a copy of the range. Failures to write are ignored: the cache only
  // saves fetches.
  void Put(const std::string& file_key, std::uint64_t offset, std::span<const std::uint8_t> bytes);

  RangeCacheStats stats() const;
  const std::string& directory() const { return directory_; }
  std::uint64_t budget_bytes() const { return budget_bytes_; }

 private:
  RangeCache(std::string directory, std::uint64_t budget_bytes);
  std::string EntryPath(const std::string& file_key, std::uint64_t offset, std::uint64_t length) const;
  // Removes the least recently used entries until the cache holds at most
  // 90 % of its budget.
  void Evict();

  std::string directory_;
  std::uint64_t budget_bytes_;
  std::atomic<std::uint64_t> bytes_{0};
  std::atomic<std::uint64_t> hits_{0};
  std::atomic<std::uint64_t> misses_{0};
  std::atomic<std::uint64_t> damaged_{0};
  std::atomic<std::uint64_t> evicted_{0};
  std::atomic<std::uint64_t> temporary_counter_{0};
  std::mutex evict_mutex_;
};

}  // namespace octocosm
