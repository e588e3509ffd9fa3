#include "storage/http_file.h"

#include <curl/curl.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstring>
#include <thread>

#include "base/error.h"
#include "storage/read_cancellation.h"

namespace octocosm {
namespace {

// Fetched at open: a page file's header and first index pages, or the whole
// of a manifest, in the request that also tells the file's size.
constexpr std::size_t kHeadBytes = 64 * 1024;

// libcurl's receive buffer: a block of 100 KB-1 MB arrives in a few reads
// instead of one per 16 KiB (libcurl's default).
constexpr long kReceiveBufferBytes = 512 * 1024;

void InitCurlOnce() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (curl_global_init(CURL_GLOBAL_DEFAULT) != CURLE_OK) {
      throw Error::Io("libcurl", "curl_global_init failed");
    }
  });
}

bool StartsWith(const std::string& text, const char* prefix) { return text.rfind(prefix, 0) == 0; }

std::string Trim(std::string text) {
  const char* space = " \t\r\n";
  text.erase(0, text.find_first_not_of(space));
  const std::size_t end = text.find_last_not_of(space);
  text.erase(end == std::string::npos ? 0 : end + 1);
  return text;
}

bool EqualsIgnoringCase(const std::string& a, const char* b) {
  const std::size_t n = std::strlen(b);
  if (a.size() != n) return false;
  for (std::size_t i = 0; i < n; ++i) {
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  }
  return true;
}

// "bytes FIRST-LAST/TOTAL", or "bytes */TOTAL" (a 416 answer: first and
// last are then absent). TOTAL may be "*" (unknown), which is refused.
struct ContentRange {
  bool valid = false;
  bool has_range = false;
  std::uint64_t first = 0;
  std::uint64_t last = 0;
  std::uint64_t total = 0;
};

bool ParseNumber(const std::string& text, std::uint64_t& value) {
  if (text.empty() || text.size() > 19) return false;
  value = 0;
  for (char c : text) {
    if (c < '0' || c > '9') return false;
    value = value * 10 + static_cast<std::uint64_t>(c - '0');
  }
  return true;
}

ContentRange ParseContentRange(const std::string& header) {
  ContentRange range;
  if (!StartsWith(header, "bytes ")) return range;
  const std::string rest = header.substr(6);
  const std::size_t slash = rest.find('/');
  if (slash == std::string::npos || !ParseNumber(rest.substr(slash + 1), range.total)) return range;
  const std::string span = rest.substr(0, slash);
  if (span == "*") {
    range.valid = true;
    return range;
  }
  const std::size_t dash = span.find('-');
  if (dash == std::string::npos || !ParseNumber(span.substr(0, dash), range.first) ||
      !ParseNumber(span.substr(dash + 1), range.last) || range.last < range.first) {
    return range;
  }
  range.valid = true;
  range.has_range = true;
  return range;
}

// One libcurl easy handle: it keeps its connection open between requests.
struct CurlHandle {
  CURL* curl = nullptr;
  char error[CURL_ERROR_SIZE] = {};
  CurlHandle() : curl(curl_easy_init()) {
    if (curl == nullptr) throw Error::Io("libcurl", "curl_easy_init failed");
  }
  ~CurlHandle() { curl_easy_cleanup(curl); }
  CurlHandle(const CurlHandle&) = delete;
  CurlHandle& operator=(const CurlHandle&) = delete;
};

// Idle handles of every HttpFile of the process: as many connections stay
// open as requests were ever in flight at once, whatever the number of files.
class CurlHandlePool {
 public:
  static CurlHandlePool& Shared() {
    static CurlHandlePool* pool = new CurlHandlePool;  // never destroyed: files may outlive statics
    return *pool;
  }
  std::unique_ptr<CurlHandle> Acquire() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!idle_.empty()) {
        std::unique_ptr<CurlHandle> handle = std::move(idle_.back());
        idle_.pop_back();
        return handle;
      }
    }
    return std::make_unique<CurlHandle>();
  }
  void Release(std::unique_ptr<CurlHandle> handle) {
    std::lock_guard<std::mutex> lock(mutex_);
    idle_.push_back(std::move(handle));
  }

 private:
  std::mutex mutex_;
  std::vector<std::unique_ptr<CurlHandle>> idle_;
};

}  // namespace

bool IsHttpUrl(const std::string& location) {
  return StartsWith(location, "http://") || StartsWith(location, "https://");
}

// What one request brought back.
struct HttpFile::Response {
  CURLcode code = CURLE_OK;
  long status = 0;
  std::string etag;
  std::string last_modified;
  std::string content_range;
  std::size_t length = 0;                 // the body expected
  std::span<const BodyPiece> pieces;      // where it goes
  std::size_t next_piece = 0;             // the first piece not yet filled
  std::size_t body_bytes = 0;             // received
  bool overflow = false;                  // the body was longer than `length`: cut off

  // Copies each arriving run of the body into the pieces it overlaps, so
  // that ranges read together need no buffer of their own.
  static std::size_t OnBody(char* data, std::size_t size, std::size_t count, void* self) {
    auto* response = static_cast<Response*>(self);
    const std::size_t bytes = size * count;
    if (bytes > response->length - response->body_bytes) {
      response->overflow = true;
      return 0;  // stops the transfer (CURLE_WRITE_ERROR)
    }
    const std::size_t begin = response->body_bytes, end = begin + bytes;
    const std::span<const BodyPiece> pieces = response->pieces;
    std::size_t& next = response->next_piece;
    while (next < pieces.size() && pieces[next].at + pieces[next].out.size() <= begin) ++next;
    for (std::size_t p = next; p < pieces.size() && pieces[p].at < end; ++p) {
      const std::size_t from = std::max(begin, pieces[p].at);
      const std::size_t to = std::min(end, pieces[p].at + pieces[p].out.size());
      if (from < to) std::memcpy(pieces[p].out.data() + (from - pieces[p].at), data + (from - begin), to - from);
    }
    response->body_bytes = end;
    return bytes;
  }

  // Called by libcurl while a transfer runs (often while bytes come, about
  // once a second while none do): a nonzero answer aborts it.
  static int OnProgress(void*, curl_off_t, curl_off_t, curl_off_t, curl_off_t) { return ReadCancelled() ? 1 : 0; }

  static std::size_t OnHeader(char* data, std::size_t size, std::size_t count, void* self) {
    auto* response = static_cast<Response*>(self);
    const std::size_t bytes = size * count;
    const std::string line(data, bytes);
    if (StartsWith(line, "HTTP/")) {
      // A new response (after a redirect or a 100 Continue): forget the last.
      response->etag.clear();
      response->last_modified.clear();
      response->content_range.clear();
      return bytes;
    }
    const std::size_t colon = line.find(':');
    if (colon == std::string::npos) return bytes;
    const std::string name = Trim(line.substr(0, colon));
    const std::string value = Trim(line.substr(colon + 1));
    if (EqualsIgnoringCase(name, "etag")) response->etag = value;
    if (EqualsIgnoringCase(name, "last-modified")) response->last_modified = value;
    if (EqualsIgnoringCase(name, "content-range")) response->content_range = value;
    return bytes;
  }
};

std::unique_ptr<HttpFile> HttpFile::Open(const std::string& url, HttpOptions options) {
  InitCurlOnce();
  std::unique_ptr<HttpFile> file(new HttpFile(url, options));
  file->head_.resize(kHeadBytes);
  Opened opened;
  const BodyPiece head{0, file->head_};
  file->FetchRange(0, file->head_.size(), {&head, 1}, &opened);
  file->head_.resize(opened.head_bytes);
  file->size_ = opened.size;
  file->etag_ = std::move(opened.etag);
  file->last_modified_ = std::move(opened.last_modified);
  if (file->options_.cache && !(file->etag_.empty() && file->last_modified_.empty())) {
    file->cache_key_ = file->url_ + "\n" + std::to_string(file->size_) + "\n" + file->etag_ + "\n" +
                       file->last_modified_;
  }
  return file;
}

HttpFile::HttpFile(std::string url, HttpOptions options) : url_(std::move(url)), options_(options) {}

HttpFile::~HttpFile() = default;

HttpStats HttpFile::stats() const {
  return HttpStats{requests_.load(), retries_.load(), bytes_fetched_.load()};
}

std::size_t HttpFile::ReadAt(std::uint64_t offset, std::span<std::uint8_t> out) const {
  if (offset >= size_ || out.empty()) return 0;
  const std::size_t length = static_cast<std::size_t>(std::min<std::uint64_t>(out.size(), size_ - offset));
  out = out.first(length);
  if (!ReadHeld(offset, out)) FetchAndCache(offset, out);
  return length;
}

bool HttpFile::ReadHeld(std::uint64_t offset, std::span<std::uint8_t> out) const {
  const std::size_t length = out.size();
  if (offset + length <= head_.size()) {
    std::memcpy(out.data(), head_.data() + offset, length);
    return true;
  }
  if (offset >= resident_offset_ && offset + length <= resident_offset_ + resident_length_) {
    // A failed fetch throws out of call_once, so the next read tries again.
    std::call_once(resident_fetched_, [this] {
      std::vector<std::uint8_t> bytes(static_cast<std::size_t>(resident_length_));
      ReadRange(resident_offset_, bytes);
      resident_ = std::move(bytes);
    });
    std::memcpy(out.data(), resident_.data() + (offset - resident_offset_), length);
    return true;
  }
  return !cache_key_.empty() && options_.cache->Get(cache_key_, offset, out);
}

void HttpFile::ReadRanges(std::span<RangeRead> ranges) const {
  CheckAscendingRanges(ranges, url_);
  std::vector<RangeRead*> missing;
  for (RangeRead& range : ranges) {
    range.got = 0;
    if (range.offset >= size_ || range.out.empty()) continue;
    range.got = static_cast<std::size_t>(std::min<std::uint64_t>(range.out.size(), size_ - range.offset));
    if (!ReadHeld(range.offset, range.out.first(range.got))) missing.push_back(&range);
  }
  if (missing.empty()) return;
  // One request for all the missing ranges: a round trip to the server costs
  // more than the few bytes between them. Each range's bytes go straight
  // into its buffer.
  const std::uint64_t first = missing.front()->offset;
  std::vector<BodyPiece> pieces;
  pieces.reserve(missing.size());
  for (const RangeRead* range : missing) {
    pieces.push_back({static_cast<std::size_t>(range->offset - first), range->out.first(range->got)});
  }
  FetchRange(first, static_cast<std::size_t>(missing.back()->offset + missing.back()->got - first), pieces, nullptr);
  if (cache_key_.empty()) return;
  for (const RangeRead* range : missing) options_.cache->Put(cache_key_, range->offset, range->out.first(range->got));
}

void HttpFile::ReadRange(std::uint64_t offset, std::span<std::uint8_t> out) const {
  if (!cache_key_.empty() && options_.cache->Get(cache_key_, offset, out)) return;
  FetchAndCache(offset, out);
}

void HttpFile::FetchAndCache(std::uint64_t offset, std::span<std::uint8_t> out) const {
  const BodyPiece whole{0, out};
  FetchRange(offset, out.size(), {&whole, 1}, nullptr);
  if (!cache_key_.empty()) options_.cache->Put(cache_key_, offset, out);
}

void HttpFile::KeepResident(std::uint64_t offset, std::uint64_t length) {
  if (offset >= size_ || length == 0 || length > kMaxResidentBytes) return;
  resident_offset_ = offset;
  resident_length_ = std::min(length, size_ - offset);
}

void HttpFile::ThrowIfReadCancelled(std::uint64_t offset, std::size_t length) const {
  if (!ReadCancelled()) return;
  throw Error::Io(url_, "bytes " + std::to_string(offset) + "-" + std::to_string(offset + length - 1) +
                            ": read cancelled (no longer wanted)");
}

void HttpFile::FetchRange(std::uint64_t offset, std::size_t length, std::span<const BodyPiece> pieces,
                          Opened* opened) const {
  std::unique_ptr<CurlHandle> handle = CurlHandlePool::Shared().Acquire();
  std::string failure;
  double backoff_s = options_.first_backoff_s;
  for (int attempt = 0;; ++attempt) {
    ThrowIfReadCancelled(offset, length);
    if (TryFetchRange(handle->curl, handle->error, offset, length, pieces, opened, failure)) break;
    if (attempt >= options_.retries) {
      throw Error::Io(url_, failure + " (gave up after " + std::to_string(attempt + 1) + " attempts)");
    }
    retries_.fetch_add(1, std::memory_order_relaxed);
    std::this_thread::sleep_for(std::chrono::duration<double>(backoff_s));
    backoff_s *= 2;
  }
  CurlHandlePool::Shared().Release(std::move(handle));
}

bool HttpFile::TryFetchRange(void* curl_handle, char* error_buffer, std::uint64_t offset, std::size_t length,
                             std::span<const BodyPiece> pieces, Opened* opened, std::string& failure) const {
  const std::uint64_t last = offset + length - 1;
  const std::string range = std::to_string(offset) + "-" + std::to_string(last);
  Response response;
  response.length = length;
  response.pieces = pieces;

  CURL* curl = static_cast<CURL*>(curl_handle);
  error_buffer[0] = '\0';
  curl_easy_setopt(curl, CURLOPT_URL, url_.c_str());
  curl_easy_setopt(curl, CURLOPT_HTTPGET, 1L);
  curl_easy_setopt(curl, CURLOPT_RANGE, range.c_str());
  curl_easy_setopt(curl, CURLOPT_FOLLOWLOCATION, 1L);
  curl_easy_setopt(curl, CURLOPT_MAXREDIRS, 5L);
  curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, error_buffer);
  curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT_MS, static_cast<long>(options_.connect_timeout_s * 1000));
  // Below 1 byte/s for the stall time: the server or the link is stuck.
  curl_easy_setopt(curl, CURLOPT_LOW_SPEED_LIMIT, 1L);
  curl_easy_setopt(curl, CURLOPT_LOW_SPEED_TIME, std::max(1L, static_cast<long>(options_.stall_timeout_s)));
  // Bodies as sent: a compressed answer would not be the bytes of the range.
  curl_easy_setopt(curl, CURLOPT_ACCEPT_ENCODING, nullptr);
  curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, &Response::OnBody);
  curl_easy_setopt(curl, CURLOPT_WRITEDATA, &response);
  curl_easy_setopt(curl, CURLOPT_HEADERFUNCTION, &Response::OnHeader);
  curl_easy_setopt(curl, CURLOPT_HEADERDATA, &response);
  curl_easy_setopt(curl, CURLOPT_XFERINFOFUNCTION, &Response::OnProgress);
  curl_easy_setopt(curl, CURLOPT_NOPROGRESS, 0L);
  curl_easy_setopt(curl, CURLOPT_BUFFERSIZE, kReceiveBufferBytes);

  requests_.fetch_add(1, std::memory_order_relaxed);
  response.code = curl_easy_perform(curl);
  curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &response.status);
  bytes_fetched_.fetch_add(response.body_bytes, std::memory_order_relaxed);

  const std::string what = "bytes " + range;
  if (response.code == CURLE_ABORTED_BY_CALLBACK) ThrowIfReadCancelled(offset, length);
  if (response.code != CURLE_OK && !(response.code == CURLE_WRITE_ERROR && response.overflow)) {
    failure = what + ": " + (error_buffer[0] != '\0' ? std::string(error_buffer) : curl_easy_strerror(response.code));
    return false;  // no connection, a timeout, a cut transfer: may pass
  }

  const long status = response.status;
  if (status == 404 || status == 410) {
    throw Error::NotFound(url_ + ": not found on the server (HTTP " + std::to_string(status) + ")");
  }
  if (status == 401 || status == 403) {
    throw Error::Io(url_, "the server refuses access (HTTP " + std::to_string(status) + ")");
  }
  if (status == 408 || status == 429 || status >= 500) {
    failure = what + ": HTTP " + std::to_string(status) + " from the server";
    return false;
  }
  if (status == 412) {
    throw Error::Corruption(url_, "changed on the server since it was opened (HTTP 412)");
  }

  const ContentRange content_range = ParseContentRange(response.content_range);
  if (status == 416) {
    // Asked past the end: an empty file at open, else one that shrank.
    if (opened != nullptr && content_range.valid && content_range.total == 0) {
      *opened = Opened{0, 0, response.etag, response.last_modified};
      return true;
    }
    throw Error::Corruption(url_, "changed on the server since it was opened: " + what +
                                      " are past its end (HTTP 416, Content-Range: " + response.content_range +
                                      ")");
  }
  if (status == 200) {
    // The whole file: acceptable only where it is the range asked for.
    if (!response.overflow && opened != nullptr) {
      *opened = Opened{response.body_bytes, response.body_bytes, response.etag, response.last_modified};
      return true;
    }
    if (!response.overflow && offset == 0 && response.body_bytes == size_) return true;
    throw Error::Io(url_, "the server ignored the range request for " + what +
                              " and sent the whole file (HTTP 200): serve the store with a server that "
                              "supports range requests (docs/REMOTE.md)");
  }
  if (status != 206) {
    throw Error::Io(url_, "unexpected answer to a range request for " + what + ": HTTP " + std::to_string(status));
  }

  if (!content_range.valid || !content_range.has_range) {
    throw Error::Io(url_, "a range answer (HTTP 206) without a usable Content-Range (\"" +
                              response.content_range + "\") for " + what);
  }
  if (opened != nullptr) {
    // The server clamps a range that runs past the end of a small file.
    if (content_range.first != 0 || content_range.last >= content_range.total ||
        response.body_bytes != content_range.last + 1 || response.overflow) {
      throw Error::Io(url_, "the server answered the first range with " + response.content_range + " and " +
                                std::to_string(response.body_bytes) + " bytes");
    }
    *opened = Opened{content_range.total, response.body_bytes, response.etag, response.last_modified};
    return true;
  }
  if (content_range.total != size_ || (!etag_.empty() && response.etag != etag_) ||
      (etag_.empty() && !last_modified_.empty() && response.last_modified != last_modified_)) {
    throw Error::Corruption(url_, "changed on the server since it was opened: it was " + std::to_string(size_) +
                                      " bytes" + (etag_.empty() ? "" : ", ETag " + etag_) +
                                      "; it is now " + std::to_string(content_range.total) + " bytes" +
                                      (response.etag.empty() ? "" : ", ETag " + response.etag));
  }
  if (content_range.first != offset || content_range.last != last) {
    throw Error::Io(url_, "the server answered a request for " + what + " with " + response.content_range);
  }
  if (response.overflow || response.body_bytes != length) {
    failure = what + ": the server sent " + std::to_string(response.body_bytes) + (response.overflow ? "+" : "") +
              " of " + std::to_string(length) + " bytes";
    return false;
  }
  return true;
}

namespace {
std::mutex default_options_mutex;
HttpOptions default_options;
}  // namespace

void SetDefaultHttpOptions(HttpOptions options) {
  std::lock_guard<std::mutex> lock(default_options_mutex);
  default_options = std::move(options);
}

HttpOptions DefaultHttpOptions() {
  std::lock_guard<std::mutex> lock(default_options_mutex);
  return default_options;
}

std::unique_ptr<ReadableFile> OpenReadableFile(const std::string& location) {
  if (IsHttpUrl(location)) return HttpFile::Open(location, DefaultHttpOptions());
  return std::make_unique<RandomAccessFile>(RandomAccessFile::Open(location));
}

}  // namespace octocosm
