#include "base/parallel_for.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <thread>
#include <vector>

namespace octocosm {
namespace {

// Runs run(part) for part in [0, parts), part 0 on the calling thread, and
// rethrows the first part's exception once all are done.
void RunParts(std::size_t parts, const std::function<void(std::size_t)>& run) {
  std::vector<std::exception_ptr> errors(parts);
  auto guarded = [&](std::size_t part) {
    try {
      run(part);
    } catch (...) {
      errors[part] = std::current_exception();
    }
  };
  std::vector<std::thread> workers;
  workers.reserve(parts - 1);
  for (std::size_t part = 1; part < parts; ++part) workers.emplace_back(guarded, part);
  guarded(0);
  for (std::thread& worker : workers) worker.join();
  for (const std::exception_ptr& error : errors) {
    if (error) std::rethrow_exception(error);
  }
}

}  // namespace

int ResolveThreadCount(int requested) {
  if (requested > 0) return requested;
  const unsigned hardware = std::thread::hardware_concurrency();
  return hardware == 0 ? 1 : static_cast<int>(hardware);
}

void ParallelFor(std::size_t count, int threads, const std::function<void(std::size_t, std::size_t)>& body,
                 std::size_t min_items_per_thread) {
  const std::size_t useful = std::max<std::size_t>(1, count / std::max<std::size_t>(1, min_items_per_thread));
  const std::size_t parts = std::min<std::size_t>(static_cast<std::size_t>(std::max(threads, 1)), useful);
  if (parts <= 1) {
    if (count > 0) body(0, count);
    return;
  }
  RunParts(parts, [&](std::size_t part) { body(count * part / parts, count * (part + 1) / parts); });
}

void ParallelForDynamic(std::size_t count, int threads, std::size_t grain,
                        const std::function<void(std::size_t, std::size_t)>& body) {
  grain = std::max<std::size_t>(grain, 1);
  const std::size_t pieces = count / grain + (count % grain != 0 ? 1 : 0);
  const std::size_t parts = std::min<std::size_t>(static_cast<std::size_t>(std::max(threads, 1)), pieces);
  if (parts <= 1) {
    if (count > 0) body(0, count);
    return;
  }
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  RunParts(parts, [&](std::size_t) {
    try {
      for (std::size_t piece = next++; piece < pieces && !failed; piece = next++) {
        body(piece * grain, std::min(count, (piece + 1) * grain));
      }
    } catch (...) {
      failed = true;
      throw;
    }
  });
}

}  // namespace octocosm
