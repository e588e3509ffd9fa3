// A file on an HTTP(S) server read with range requests (libcurl), so that a
// store directory served by any static server (nginx, Apache, an object
// store) reads like a local one. docs/REMOTE.md says how to serve one.
//
// Every read is checked: a 206 answer whose Content-Range is the range asked
// for, whose body is exactly that long, from a file whose size and validator
// (ETag, else Last-Modified) are those seen at open. A file replaced on the
// server while it is read is kCorruption, never a mix of two versions; a
// server that ignores ranges is kIo saying so. Failures that may pass (no
// connection, a stalled or cut transfer, 5xx, 429) are retried a bounded
// number of times, then kIo naming the URL and the last failure. A read
// whose caller cancels it (storage/read_cancellation.h) stops its transfer.
//
// Thread-safe: each read borrows a libcurl handle from a pool the process's
// files share, so reads on several threads are several requests in flight,
// and a handle keeps its connection alive for the next request to that server.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "storage/file.h"
#include "storage/range_cache.h"

namespace octocosm {

struct HttpOptions {
  double connect_timeout_s = 10;
  // A transfer that moves no byte for this long fails (and is retried).
  double stall_timeout_s = 20;
  // Further attempts after the first, for failures that may pass.
  int retries = 3;
  // Wait before the first retry; doubled before each next one.
  double first_backoff_s = 0.25;
  // Where fetched ranges are kept between runs (none: fetched every run).
  // Only files with a validator (ETag or Last-Modified) are cached.
  std::shared_ptr<RangeCache> cache;
};

// The options OpenReadableFile gives HTTP files: the program sets them once
// from its flags (--cache-dir), before it opens a store.
void SetDefaultHttpOptions(HttpOptions options);
HttpOptions DefaultHttpOptions();

// A resident range longer than this is read piece by piece like the rest.
inline constexpr std::uint64_t kMaxResidentBytes = 64 << 20;

// Counters of one file's requests; a snapshot.
struct HttpStats {
  std::uint64_t requests = 0;  // requests sent, retries included
  std::uint64_t retries = 0;
  std::uint64_t bytes_fetched = 0;  // body bytes received
};

// True for "http://..." and "https://...".
bool IsHttpUrl(const std::string& location);

class HttpFile final : public ReadableFile {
 public:
  // Fetches the first bytes of the file (one request: its size, validator and
  // header come back together). Throws kNotFound for 404/410, kIo for a server
  // that cannot be reached, refuses access or ignores range requests.
  static std::unique_ptr<HttpFile> Open(const std::string& url, HttpOptions options = {});

  ~HttpFile() override;
  HttpFile(const HttpFile&) = delete;
  HttpFile& operator=(const HttpFile&) = delete;

  std::size_t ReadAt(std::uint64_t offset, std::span<std::uint8_t> out) const override;
  void ReadRanges(std::span<RangeRead> ranges) const override;
  std::uint64_t Size() const override { return size_; }
  const std::string& path() const override { return url_; }
  bool remote() const override { return true; }
  void KeepResident(std::uint64_t offset, std::uint64_t length) override;

  HttpStats stats() const;

 private:
  struct Response;
  // What the first request tells about the file.
  struct Opened {
    std::uint64_t size = 0;
    std::size_t head_bytes = 0;
    std::string etag;
    std::string last_modified;
  };

  HttpFile(std::string url, HttpOptions options);
  // Fills `out` (within the file) from what is held without a request of its
  // own: the head, the resident range (fetched whole at its first read), the
  // cache. False when it must be fetched.
  bool ReadHeld(std::uint64_t offset, std::span<std::uint8_t> out) const;
  // A range from the cache, else fetched (and then cached).
  void ReadRange(std::uint64_t offset, std::span<std::uint8_t> out) const;
  void FetchAndCache(std::uint64_t offset, std::span<std::uint8_t> out) const;
  // Where the body of one range request goes: its bytes [at, at +
  // out.size()) into `out`. Pieces ascend without overlapping; the bytes
  // between them are dropped as they arrive.
  struct BodyPiece {
    std::size_t at = 0;
    std::span<std::uint8_t> out;
  };
  // One range request with retries for exactly bytes [offset, offset +
  // length) of the file, each piece filled, or throws. At open (`opened`
  // not null) the file's size is not known yet: the answer may be shorter
  // than `length` and tells the size and validators.
  void FetchRange(std::uint64_t offset, std::size_t length, std::span<const BodyPiece> pieces,
                  Opened* opened) const;
  // Throws kIo "read cancelled" when the read on this thread is
  // (storage/read_cancellation.h).
  void ThrowIfReadCancelled(std::uint64_t offset, std::size_t length) const;
  // One attempt. Returns false for a failure worth retrying (described in
  // `failure`); throws for one that is not.
  bool TryFetchRange(void* curl, char* error_buffer, std::uint64_t offset, std::size_t length,
                     std::span<const BodyPiece> pieces, Opened* opened, std::string& failure) const;

  std::string url_;
  HttpOptions options_;
  std::uint64_t size_ = 0;
  std::string etag_;
  std::string last_modified_;
  // The file's name in options_.cache; empty when it is not cached.
  std::string cache_key_;
  // The first bytes of the file, fetched at open: the header of a page file,
  // or all of a small file such as a manifest.
  std::vector<std::uint8_t> head_;
  // The range declared by KeepResident, fetched whole at its first read.
  std::uint64_t resident_offset_ = 0;
  std::uint64_t resident_length_ = 0;
  mutable std::once_flag resident_fetched_;
  mutable std::vector<std::uint8_t> resident_;

  mutable std::atomic<std::uint64_t> requests_{0};
  mutable std::atomic<std::uint64_t> retries_{0};
  mutable std::atomic<std::uint64_t> bytes_fetched_{0};
};

// A path, or an http(s) URL opened with DefaultHttpOptions().
std::unique_ptr<ReadableFile> OpenReadableFile(const std::string& location);

}  // namespace octocosm
