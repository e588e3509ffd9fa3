// Writes ranges of an existing file with O_DIRECT, on a background thread.
//
// A store is written once and read later, so copying its gigabytes through
// the page cache buys nothing and costs twice: the copy itself and the
// kernel's writeback, both on the cores the ingest is using. O_DIRECT hands
// the bytes to the disk from this process's own memory instead; a background
// thread does the waiting, so the threads that produce blocks go on.
//
// Direct I/O wants buffers, offsets and lengths aligned to the device's
// logical block; kAlignment (4 KiB) covers every common device. Write()
// copies the bytes into an aligned buffer from a reused pool (bounded by
// `max_bytes_in_flight`) and zero-pads them to a whole number of
// kAlignment units: the caller owns the range up to that boundary. Queued
// writes that continue each other on disk go out in one call (pwritev): one
// small write at a time would wait for the disk once each, and on the
// virtual machines this project runs on each call costs a request to the
// host (a 10^8-point ingest's 40,000 block writes of about 160 KiB, one call
// each, took 5 % of its CPU). So the background thread waits until a batch's
// worth is queued (kMaxBatchBytes or kMaxBatchJobs), or someone waits for
// memory or calls Drain(), and writes the queued jobs in offset order. Where the
// file system refuses O_DIRECT (tmpfs before Linux 6.6) Open() returns
// nullptr, and where a device refuses a write for its alignment the writer
// falls back to ordinary writes for the rest of its life: slower, never wrong.
//
// Errors surface late: a failed write is reported (kIo, naming the file and
// offset) by the next Write() or by Drain(); writes queued behind it are
// dropped. Drain() before relying on the file's contents.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <exception>
#include <memory>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "base/mutex.h"
#include "storage/file.h"

namespace octocosm {

class DirectWriter {
 public:
  static constexpr std::size_t kAlignment = 4096;
  // At most this many queued writes, and bytes, go to the disk in one call.
  static constexpr std::size_t kMaxBatchJobs = 64;
  static constexpr std::size_t kMaxBatchBytes = std::size_t{4} << 20;

  // Opens `path`, which must exist, for direct writes; nullptr where the file
  // system does not support them. kIo for any other failure to open.
  static std::unique_ptr<DirectWriter> Open(const std::string& path, std::size_t max_bytes_in_flight);

  DirectWriter(const DirectWriter&) = delete;
  DirectWriter& operator=(const DirectWriter&) = delete;
  // Stops the thread; writes still queued are dropped (Drain() keeps them).
  ~DirectWriter();

  // Queues `bytes` for writing at `offset`, a multiple of kAlignment (else
  // kInvalidArgument), followed by zeros up to the next multiple. Safe to call
  // from several threads at once for ranges that do not overlap. Waits while
  // max_bytes_in_flight bytes are queued (a single larger write still goes).
  // Throws an earlier write's failure.
  void Write(std::uint64_t offset, std::span<const std::uint8_t> bytes) EXCLUDES(mutex_);

  // Writes everything queued and waits until it is on its way to the disk
  // (not fsynced); throws the first failure.
  void Drain() EXCLUDES(mutex_);

 private:
  struct AlignedFree {
    void operator()(std::uint8_t* p) const;
  };
  using Buffer = std::unique_ptr<std::uint8_t[], AlignedFree>;
  struct Buffered {
    Buffer buffer;
    std::size_t capacity = 0;
  };
  struct Job {
    std::uint64_t offset = 0;
    std::size_t length = 0;  // a multiple of kAlignment
    Buffered memory;
  };

  DirectWriter(std::string path, UniqueFd direct, UniqueFd plain, std::size_t max_bytes_in_flight);
  // Waits (releasing mutex_) while the memory in flight is at its limit.
  Buffered Acquire(std::size_t capacity) REQUIRES(mutex_);
  void ThrowIfFailed() const REQUIRES(mutex_);
  void Run() EXCLUDES(mutex_);
  // Whether the thread should write now rather than wait for more jobs.
  bool BatchDue() const REQUIRES(mutex_);
  // Takes the queued job with the lowest offset and those that continue it.
  void TakeBatch(std::vector<Job>& batch) REQUIRES(mutex_);
  // Writes jobs that follow each other on disk with one call.
  void WriteFully(const std::vector<Job>& batch);

  const std::string path_;
  const UniqueFd direct_;
  const UniqueFd plain_;  // for the fallback
  const std::size_t max_bytes_in_flight_;

  mutable Mutex mutex_;
  CondVar work_;      // a job was queued, or stopping
  CondVar progress_;  // a job finished: memory or Drain may proceed
  std::deque<Job> queue_ GUARDED_BY(mutex_);
  std::size_t queued_bytes_ GUARDED_BY(mutex_) = 0;
  std::size_t waiting_ GUARDED_BY(mutex_) = 0;  // threads waiting for memory or in Drain
  std::vector<Buffered> free_ GUARDED_BY(mutex_);
  std::size_t allocated_bytes_ GUARDED_BY(mutex_) = 0;
  std::size_t jobs_unfinished_ GUARDED_BY(mutex_) = 0;  // queued or being written
  std::exception_ptr failure_ GUARDED_BY(mutex_);
  bool stopping_ GUARDED_BY(mutex_) = false;
  bool fell_back_ = false;  // the writer thread's alone: no lock
  std::thread thread_;  // last: starts once the members above exist
};

}  // namespace octocosm
