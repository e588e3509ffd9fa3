#include "tools/ingest/spill_writer.h"

#include <utility>

namespace octocosm {

SpillWriter::SpillWriter() : thread_([this] { Run(); }) {}

SpillWriter::~SpillWriter() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
    jobs_.clear();
  }
  work_ready_.notify_one();
  thread_.join();
}

void SpillWriter::Submit(ParticleFileWriter& file, ParticleChunk points) {
  const std::uint64_t count = points.size();
  {
    std::lock_guard lock(mutex_);
    RethrowLocked();
    jobs_.push_back({&file, std::move(points)});
    pending_points_ += count;
  }
  work_ready_.notify_one();
}

void SpillWriter::WaitForPendingAtMost(std::uint64_t points) {
  std::unique_lock lock(mutex_);
  written_.wait(lock, [&] { return pending_points_ <= points || error_; });
  RethrowLocked();
}

std::uint64_t SpillWriter::pending_points() const {
  std::lock_guard lock(mutex_);
  return pending_points_;
}

void SpillWriter::RethrowLocked() {
  if (error_) std::rethrow_exception(error_);
}

void SpillWriter::Run() {
  std::unique_lock lock(mutex_);
  for (;;) {
    work_ready_.wait(lock, [&] { return stop_ || !jobs_.empty(); });
    if (stop_) return;
    Job job = std::move(jobs_.front());
    jobs_.pop_front();
    lock.unlock();
    std::exception_ptr error;
    try {
      job.file->Append(job.points);
    } catch (...) {
      error = std::current_exception();
    }
    const std::uint64_t count = job.points.size();
    job.points = ParticleChunk();  // the memory goes back before the caller is told it did
    lock.lock();
    pending_points_ -= count;
    if (error && !error_) error_ = error;
    if (error_) {
      // Later batches would leave holes in their files: drop them.
      for (const Job& dropped : jobs_) pending_points_ -= dropped.points.size();
      jobs_.clear();
    }
    written_.notify_all();
  }
}

}  // namespace octocosm
