#include "storage/direct_writer.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>

#include "base/error.h"

namespace octocosm {
namespace {

std::size_t RoundUp(std::size_t bytes) {
  return (bytes + DirectWriter::kAlignment - 1) / DirectWriter::kAlignment * DirectWriter::kAlignment;
}

}  // namespace

void DirectWriter::AlignedFree::operator()(std::uint8_t* p) const { std::free(p); }

std::unique_ptr<DirectWriter> DirectWriter::Open(const std::string& path, std::size_t max_bytes_in_flight) {
  int direct = ::open(path.c_str(), O_WRONLY | O_DIRECT | O_CLOEXEC);
  if (direct < 0) {
    if (errno == EINVAL) return nullptr;  // the file system has no direct I/O
    throw IoErrorFromErrno(path, "open for direct writes", errno);
  }
  UniqueFd direct_fd(direct);
  int plain = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (plain < 0) throw IoErrorFromErrno(path, "open for writing", errno);
  return std::unique_ptr<DirectWriter>(
      new DirectWriter(path, std::move(direct_fd), UniqueFd(plain), std::max(max_bytes_in_flight, kAlignment)));
}

DirectWriter::DirectWriter(std::string path, UniqueFd direct, UniqueFd plain, std::size_t max_bytes_in_flight)
    : path_(std::move(path)),
      direct_(std::move(direct)),
      plain_(std::move(plain)),
      max_bytes_in_flight_(max_bytes_in_flight),
      thread_([this] { Run(); }) {}

DirectWriter::~DirectWriter() {
  {
    MutexLock lock(mutex_);
    stopping_ = true;
    queue_.clear();
  }
  work_.SignalAll();
  thread_.join();
}

void DirectWriter::ThrowIfFailed() const {
  if (failure_) std::rethrow_exception(failure_);
}

DirectWriter::Buffered DirectWriter::Acquire(std::size_t capacity) {
  for (;;) {
    ThrowIfFailed();
    // The smallest free buffer that is large enough.
    auto fit = free_.end();
    for (auto it = free_.begin(); it != free_.end(); ++it) {
      if (it->capacity >= capacity && (fit == free_.end() || it->capacity < fit->capacity)) fit = it;
    }
    if (fit != free_.end()) {
      Buffered found = std::move(*fit);
      free_.erase(fit);
      return found;
    }
    if (allocated_bytes_ + capacity <= max_bytes_in_flight_ || allocated_bytes_ == 0) {
      void* memory = std::aligned_alloc(kAlignment, capacity);
      if (memory == nullptr) throw std::bad_alloc();
      allocated_bytes_ += capacity;
      return Buffered{Buffer(static_cast<std::uint8_t*>(memory)), capacity};
    }
    if (!free_.empty()) {  // too small for this write: give the memory back and try again
      allocated_bytes_ -= free_.back().capacity;
      free_.pop_back();
      continue;
    }
    ++waiting_;  // the queue goes out now instead of waiting for a whole batch
    work_.Signal();
    progress_.Wait(mutex_);
    --waiting_;
  }
}

void DirectWriter::Write(std::uint64_t offset, std::span<const std::uint8_t> bytes) {
  if (offset % kAlignment != 0) {
    throw Error::InvalidArgument("direct write to " + path_ + " at offset " + std::to_string(offset) +
                                 ", not a multiple of " + std::to_string(kAlignment));
  }
  if (bytes.empty()) return;
  const std::size_t length = RoundUp(bytes.size());
  Job job;
  job.offset = offset;
  job.length = length;
  {
    MutexLock lock(mutex_);
    job.memory = Acquire(length);
  }
  // The copy runs outside the lock: other threads queue their own meanwhile.
  std::memcpy(job.memory.buffer.get(), bytes.data(), bytes.size());
  std::memset(job.memory.buffer.get() + bytes.size(), 0, length - bytes.size());
  bool due = false;
  {
    MutexLock lock(mutex_);
    ThrowIfFailed();
    queued_bytes_ += job.length;
    queue_.push_back(std::move(job));
    ++jobs_unfinished_;
    due = BatchDue();
  }
  // Woken for every block, the writer thread only found the batch short and
  // slept again: 1,800 wake-ups at 10^7 points, each taking a core from a
  // build thread for a moment.
  if (due) work_.Signal();
}

void DirectWriter::Drain() {
  MutexLock lock(mutex_);
  ++waiting_;
  work_.Signal();
  while (jobs_unfinished_ != 0 && !failure_) progress_.Wait(mutex_);
  --waiting_;
  ThrowIfFailed();
}

bool DirectWriter::BatchDue() const {
  return !queue_.empty() && (queued_bytes_ >= kMaxBatchBytes || queue_.size() >= kMaxBatchJobs || waiting_ > 0);
}

void DirectWriter::TakeBatch(std::vector<Job>& batch) {
  // Several threads queue jobs a little out of order; in offset order they
  // mostly continue each other.
  std::sort(queue_.begin(), queue_.end(), [](const Job& a, const Job& b) { return a.offset < b.offset; });
  batch.clear();
  std::size_t batch_bytes = 0;
  do {
    batch_bytes += queue_.front().length;
    batch.push_back(std::move(queue_.front()));
    queue_.pop_front();
  } while (!queue_.empty() && batch.size() < kMaxBatchJobs && batch_bytes < kMaxBatchBytes &&
           queue_.front().offset == batch.back().offset + batch.back().length);
  queued_bytes_ -= batch_bytes;
}

void DirectWriter::WriteFully(const std::vector<Job>& batch) {
  std::vector<std::span<const std::uint8_t>> parts;
  parts.reserve(batch.size());
  for (const Job& job : batch) parts.emplace_back(job.memory.buffer.get(), job.length);
  const std::uint64_t offset = batch.front().offset;
  int error = fell_back_ ? EINVAL : WriteAllAt(direct_.get(), offset, parts);
  if (error == EINVAL) {  // the device wants a coarser alignment: write through the page cache
    fell_back_ = true;
    error = WriteAllAt(plain_.get(), offset, parts);
  }
  if (error != 0) {
    const std::uint64_t length = batch.back().offset + batch.back().length - offset;
    throw IoErrorFromErrno(path_, "write of " + std::to_string(length) + " bytes at offset " + std::to_string(offset),
                           error);
  }
}

void DirectWriter::Run() {
  MutexLock lock(mutex_);
  std::vector<Job> batch;
  for (;;) {
    while (!stopping_ && !BatchDue()) work_.Wait(mutex_);
    if (stopping_) return;
    // Small writes one by one would each wait for the disk (64 KiB direct
    // writes one at a time ran at a quarter of the disk's speed here) and
    // each cost a request to the host.
    TakeBatch(batch);
    lock.Unlock();
    std::exception_ptr failed;
    try {
      WriteFully(batch);
    } catch (...) {
      failed = std::current_exception();
    }
    lock.Lock();
    for (Job& job : batch) free_.push_back(std::move(job.memory));
    jobs_unfinished_ -= batch.size();
    if (failed && !failure_) {
      failure_ = failed;
      jobs_unfinished_ -= queue_.size();  // dropped: the file is lost anyway
      for (Job& dropped : queue_) free_.push_back(std::move(dropped.memory));
      queue_.clear();
      queued_bytes_ = 0;
    }
    progress_.SignalAll();
  }
}

}  // namespace octocosm
