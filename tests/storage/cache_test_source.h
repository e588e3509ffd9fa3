// An in-memory BlockSource for the cache and prefetcher tests. Block contents
// are a pure function of the id, so any reader can check what it got. The
// source counts and records reads, can fail chosen blocks, add a delay, and
// hold reads at a closed gate so that a test can arrange concurrent misses
// deterministically. With coalescing on it behaves as a store on a server:
// block k of an epoch lies at byte k * 1000 of its file, and ReadBlocks
// records each call as one read of several blocks.
#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <mutex>
#include <optional>
#include <span>
#include <thread>
#include <unordered_map>
#include <vector>

#include "base/error.h"
#include "storage/block_source.h"
#include "storage/read_cancellation.h"

namespace octocosm::cachetest {

class CacheTestSource : public BlockSource {
 public:
  explicit CacheTestSource(std::size_t default_size = 256) : default_size_(default_size) {}

  static Bytes ContentOf(const BlockId& id, std::size_t size) {
    Bytes bytes(size);
    for (std::size_t i = 0; i < size; ++i) {
      bytes[i] = static_cast<std::uint8_t>(id.key * 31 + id.epoch * 7 + i);
    }
    return bytes;
  }
  Bytes ContentOf(const BlockId& id) const { return ContentOf(id, SizeOf(id)); }

  void SetSize(const BlockId& id, std::size_t size) {
    std::lock_guard lock(mutex_);
    sizes_[id] = size;
  }
  std::size_t SizeOf(const BlockId& id) const {
    std::lock_guard lock(mutex_);
    auto it = sizes_.find(id);
    return it == sizes_.end() ? default_size_ : it->second;
  }

  // Reads of `id` throw `error` (after passing the gate) until ClearFailure.
  void FailWith(const BlockId& id, const Error& error) {
    std::lock_guard lock(mutex_);
    failures_.insert_or_assign(id, error);
  }
  void ClearFailure(const BlockId& id) {
    std::lock_guard lock(mutex_);
    failures_.erase(id);
  }

  // The next read of `id` behaves as a read from a silent server: it waits
  // until the reading thread's read is cancelled
  // (storage/read_cancellation.h), then throws kIo "read cancelled". Later
  // reads return the block as usual.
  void SilentOnce(const BlockId& id) {
    std::lock_guard lock(mutex_);
    silent_.push_back(id);
  }

  void SetDelay(std::chrono::microseconds delay) {
    std::lock_guard lock(mutex_);
    delay_ = delay;
  }

  // While the gate is closed, reads are recorded as started and then wait.
  void CloseGate() {
    std::lock_guard lock(mutex_);
    gate_open_ = false;
  }
  void OpenGate() {
    {
      std::lock_guard lock(mutex_);
      gate_open_ = true;
    }
    changed_.notify_all();
  }

  // Waits (up to a generous timeout, so a bug fails instead of hanging) until
  // at least `count` reads have started; returns whether they did.
  bool WaitForReadsStarted(std::size_t count) const {
    std::unique_lock lock(mutex_);
    return changed_.wait_for(lock, std::chrono::seconds(20),
                             [&] { return order_.size() >= count; });
  }

  std::size_t ReadsOf(const BlockId& id) const {
    std::lock_guard lock(mutex_);
    auto it = reads_.find(id);
    return it == reads_.end() ? 0 : it->second;
  }
  std::size_t TotalReads() const {
    std::lock_guard lock(mutex_);
    return order_.size();
  }
  // Ids in the order their reads started.
  std::vector<BlockId> ReadOrder() const {
    std::lock_guard lock(mutex_);
    return order_;
  }

  void EnableCoalescing() { coalescing_ = true; }
  bool CoalescesReads() const override { return coalescing_; }
  std::optional<BlockExtent> Locate(const BlockId& id) const override {
    if (!coalescing_) return std::nullopt;
    return BlockExtent{id.key * 1000, SizeOf(id)};
  }
  // ReadBlocks calls, each with its blocks.
  std::vector<std::vector<BlockId>> Batches() const {
    std::lock_guard lock(mutex_);
    return batches_;
  }
  // One read for all: the gate, the delay and a silence (any block's) once,
  // then the first failing block's error or every block.
  void ReadBlocks(std::span<const BlockId> ids, std::span<Bytes> buffers) const override {
    {
      std::lock_guard lock(mutex_);
      batches_.emplace_back(ids.begin(), ids.end());
    }
    std::optional<Error> failure;
    bool silent = false;
    for (std::size_t i = 0; i < ids.size(); ++i) {
      Admission admission = Admit(ids[i], /*wait=*/i == 0);
      if (admission.failure && !failure) failure = admission.failure;
      silent = silent || admission.silent;
      buffers[i] = ContentOf(ids[i], admission.size);
    }
    if (failure) throw *failure;
    if (silent) WaitUntilCancelled();
  }

  Bytes ReadBlock(const BlockId& id) const override {
    Admission admission = Admit(id, /*wait=*/true);
    if (admission.failure) throw *admission.failure;
    if (admission.silent) WaitUntilCancelled();
    return ContentOf(id, admission.size);
  }

 private:
  struct Admission {
    std::optional<Error> failure;
    bool silent = false;
    std::size_t size = 0;
  };
  // Records the read of `id`; with `wait`, passes the gate and sleeps the
  // delay.
  Admission Admit(const BlockId& id, bool wait) const {
    Admission admission;
    std::chrono::microseconds delay{};
    {
      std::unique_lock lock(mutex_);
      order_.push_back(id);
      ++reads_[id];
      changed_.notify_all();
      if (wait) changed_.wait(lock, [&] { return gate_open_; });
      if (auto it = failures_.find(id); it != failures_.end()) admission.failure = it->second;
      delay = delay_;
      if (auto it = std::find(silent_.begin(), silent_.end(), id); it != silent_.end()) {
        admission.silent = true;
        silent_.erase(it);
      }
      auto size_it = sizes_.find(id);
      admission.size = size_it == sizes_.end() ? default_size_ : size_it->second;
    }
    if (wait && delay.count() > 0) std::this_thread::sleep_for(delay);
    return admission;
  }
  [[noreturn]] static void WaitUntilCancelled() {
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);  // a bug fails, not hangs
    while (!ReadCancelled() && std::chrono::steady_clock::now() < give_up) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    throw Error::Io("test server", "read cancelled (no longer wanted)");
  }

  const std::size_t default_size_;
  mutable std::mutex mutex_;
  mutable std::condition_variable changed_;
  std::unordered_map<BlockId, std::size_t, BlockIdHash> sizes_;
  std::unordered_map<BlockId, Error, BlockIdHash> failures_;
  std::chrono::microseconds delay_{0};
  mutable std::vector<BlockId> silent_;  // taken by the read they silence
  bool gate_open_ = true;
  mutable std::vector<BlockId> order_;
  mutable std::unordered_map<BlockId, std::size_t, BlockIdHash> reads_;
  bool coalescing_ = false;
  mutable std::vector<std::vector<BlockId>> batches_;
};

// Opens the gate when it goes out of scope. Declared after the threads or
// Prefetcher that may be stuck at the gate, it runs before they are joined, so
// a failed assertion ends the test instead of hanging it.
class OpenGateOnExit {
 public:
  explicit OpenGateOnExit(CacheTestSource& source) : source_(source) {}
  OpenGateOnExit(const OpenGateOnExit&) = delete;
  OpenGateOnExit& operator=(const OpenGateOnExit&) = delete;
  ~OpenGateOnExit() {
    if (armed_) source_.OpenGate();
  }
  // For a test that hands the opening to someone else once set up.
  void Dismiss() { armed_ = false; }

 private:
  CacheTestSource& source_;
  bool armed_ = true;
};

// A BlockId from a small integer, for readable tests.
inline BlockId Block(std::uint64_t key, std::uint32_t epoch = 0) { return BlockId{epoch, key}; }

}  // namespace octocosm::cachetest
