#include "base/progress.h"

#include "base/cancellation.h"

#include <unistd.h>

#include <atomic>
#include <algorithm>
#include <cmath>

namespace octocosm {
namespace {

std::atomic<bool> g_quiet{false};

std::string FormatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  const auto s = static_cast<long long>(seconds + 0.5);
  char buffer[32];
  if (s >= 3600) {
    std::snprintf(buffer, sizeof buffer, "%lldh%02lldm", s / 3600, (s / 60) % 60);
  } else if (s >= 60) {
    std::snprintf(buffer, sizeof buffer, "%lldm%02llds", s / 60, s % 60);
  } else {
    std::snprintf(buffer, sizeof buffer, "%llds", s);
  }
  return buffer;
}

}  // namespace

std::string HumanCount(double value) {
  static const char* const kSuffix[] = {"", " k", " M", " G", " T"};
  int i = 0;
  while (std::fabs(value) >= 1000.0 && i < 4) {
    value /= 1000.0;
    ++i;
  }
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, i == 0 ? "%.0f%s" : "%.1f%s", value, kSuffix[i]);
  return buffer;
}

void Progress::SetQuiet(bool quiet) { g_quiet = quiet; }

Progress::Progress(std::string phase, std::uint64_t total, std::string unit, std::FILE* out)
    : phase_(std::move(phase)),
      unit_(std::move(unit)),
      total_(total),
      out_(out),
      is_terminal_(isatty(fileno(out)) == 1),
      start_(Clock::now()),
      last_draw_(start_) {}

Progress::~Progress() { Finish(); }

void Progress::Add(std::uint64_t done) {
  ThrowIfCancelled();
  MutexLock lock(mutex_);
  done_ += done;
  const auto now = Clock::now();
  const auto interval = is_terminal_ ? std::chrono::milliseconds(100) : std::chrono::milliseconds(5000);
  if (now - last_draw_ >= interval) {
    last_draw_ = now;
    Draw(false);
  }
}

void Progress::Restart() {
  MutexLock lock(mutex_);
  done_ = 0;
  start_ = Clock::now();
}

void Progress::Finish() {
  MutexLock lock(mutex_);
  if (finished_) return;
  finished_ = true;
  Draw(true);
}

void Progress::Draw(bool final_line) {
  if (g_quiet) return;
  const double elapsed = std::chrono::duration<double>(Clock::now() - start_).count();
  const double rate = elapsed > 0 ? static_cast<double>(done_) / elapsed : 0.0;
  std::string line = phase_ + ": " + HumanCount(static_cast<double>(done_));
  if (total_ > 0) line += " / " + HumanCount(static_cast<double>(total_));
  line += " " + unit_ + ", " + HumanCount(rate) + " " + unit_ + "/s";
  if (final_line) {
    line += ", " + FormatDuration(elapsed);
  } else if (total_ > 0 && rate > 0 && done_ <= total_) {
    line += ", ETA " + FormatDuration(static_cast<double>(total_ - done_) / rate);
  }
  if (is_terminal_) {
    std::string bar;
    if (total_ > 0) {
      const double fraction = std::min(1.0, static_cast<double>(done_) / static_cast<double>(total_));
      const int width = 30;
      const int filled = static_cast<int>(fraction * width);
      bar = "[" + std::string(static_cast<std::size_t>(filled), '#') +
            std::string(static_cast<std::size_t>(width - filled), '.') + "] ";
      char percent[16];
      std::snprintf(percent, sizeof percent, "%3.0f%% ", fraction * 100.0);
      bar += percent;
    }
    std::fprintf(out_, "\r\033[K%s%s%s", bar.c_str(), line.c_str(), final_line ? "\n" : "");
  } else {
    std::fprintf(out_, "%s\n", line.c_str());
  }
  std::fflush(out_);
}

}  // namespace octocosm
