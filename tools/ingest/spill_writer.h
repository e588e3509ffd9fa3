// Appends spilled point buffers to their temporary particle files on a thread
// of its own, so that the chunker bins and gathers points on one core while
// the kernel copies the spilled bytes into the page cache on the other.
// (Measured for 10^7 points: that copy was about 40 % of the CPU time of the
// single-threaded read + chunk pass, the reading and decoding of the snapshot
// under 10 %; docs/BENCHMARKS.md.)
//
// Batches are appended in the order they were submitted, so a file holds the
// same bytes as if the caller had appended them itself. The points queued or
// being written are counted (`pending_points`) so that the caller can keep
// them inside its memory share.
//
// An error on the writing thread (a full disk) is kept and rethrown, as the
// same exception, by the caller's next Submit, WaitForPendingAtMost or Drain;
// batches submitted after it are dropped. The destructor drops whatever is
// still queued and joins the thread, so a caller that unwinds after its own
// error leaves no thread behind.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <exception>
#include <mutex>
#include <thread>

#include "index/particle_chunk.h"
#include "tools/ingest/particle_file.h"

namespace octocosm {

class SpillWriter {
 public:
  SpillWriter();
  ~SpillWriter();
  SpillWriter(const SpillWriter&) = delete;
  SpillWriter& operator=(const SpillWriter&) = delete;

  // Queues `points` to be appended to `file`. The caller must not touch
  // `file` again before Drain returns, and it must outlive this object.
  void Submit(ParticleFileWriter& file, ParticleChunk points);

  // Blocks until at most `points` points are queued or being written.
  void WaitForPendingAtMost(std::uint64_t points);

  // Blocks until every submitted batch is written.
  void Drain() { WaitForPendingAtMost(0); }

  std::uint64_t pending_points() const;

 private:
  struct Job {
    ParticleFileWriter* file;
    ParticleChunk points;
  };

  void Run();
  void RethrowLocked();  // with mutex_ held

  mutable std::mutex mutex_;
  std::condition_variable work_ready_;  // to the writing thread: a job, or stop
  std::condition_variable written_;     // to the caller: pending_points_ fell, or an error
  std::deque<Job> jobs_;
  std::uint64_t pending_points_ = 0;  // in jobs_ and in the job being written
  std::exception_ptr error_;
  bool stop_ = false;
  std::thread thread_;  // last: started once the members above exist
};

}  // namespace octocosm
