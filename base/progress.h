// Operator feedback for long jobs: a bar with rate and ETA when stderr is a
// terminal, plain progress lines (at most one every few seconds) when it is
// not, so logs from batch jobs stay readable.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

#include "base/mutex.h"

namespace octocosm {

class Progress {
 public:
  // `total` may be 0 when unknown (then no percentage or ETA is shown).
  // `unit` names what is counted ("points", "blocks", "MB").
  Progress(std::string phase, std::uint64_t total, std::string unit, std::FILE* out = stderr);
  ~Progress();  // prints the final line if Finish() was not called

  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // Thread-safe; cheap when called often (redraws at most ~10 times a second).
  // Throws "interrupted" once cancellation is requested (base/cancellation.h).
  void Add(std::uint64_t done) EXCLUDES(mutex_);
  void Finish() EXCLUDES(mutex_);
  // Counts from zero again, for a phase that starts over another way.
  void Restart() EXCLUDES(mutex_);

  // Disables all output (tests, --quiet).
  static void SetQuiet(bool quiet);

 private:
  void Draw(bool final_line) REQUIRES(mutex_);

  using Clock = std::chrono::steady_clock;
  Mutex mutex_;
  std::string phase_;
  std::string unit_;
  std::uint64_t total_;
  std::uint64_t done_ GUARDED_BY(mutex_) = 0;
  std::FILE* out_;
  bool is_terminal_;
  bool finished_ GUARDED_BY(mutex_) = false;
  Clock::time_point start_ GUARDED_BY(mutex_);
  Clock::time_point last_draw_ GUARDED_BY(mutex_);
};

// "12.3 M", "456 k": compact counts for progress lines and reports.
std::string HumanCount(double value);

}  // namespace octocosm
