#include "base/parallel_for.h"

#include <sched.h>

#include <algorithm>
#include <atomic>
#include <exception>
#include <thread>
#include <vector>

#include "base/mutex.h"

namespace octocosm {

void RunWorkers(int threads, const std::function<void(int worker, const std::atomic<bool>& stop)>& work) {
  std::atomic<bool> stop{false};
  Mutex mutex;
  std::exception_ptr first_error;  // guarded by mutex
  auto guarded = [&](int worker) {
    try {
      work(worker, stop);
    } catch (...) {
      MutexLock lock(mutex);
      if (!first_error) first_error = std::current_exception();
      stop = true;
    }
  };
  {
    std::vector<std::jthread> helpers;
    helpers.reserve(static_cast<std::size_t>(std::max(threads, 1) - 1));
    for (int worker = 1; worker < threads; ++worker) helpers.emplace_back(guarded, worker);
    guarded(0);
  }
  MutexLock lock(mutex);
  if (first_error) std::rethrow_exception(first_error);
}

unsigned CoresAllowed() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (::sched_getaffinity(0, sizeof set, &set) == 0 && CPU_COUNT(&set) > 0) return static_cast<unsigned>(CPU_COUNT(&set));
  return std::max(1u, std::thread::hardware_concurrency());
}

int ResolveThreadCount(int requested) {
  if (requested > 0) return requested;
  return static_cast<int>(CoresAllowed());
}

void ParallelFor(std::size_t count, int threads, const std::function<void(std::size_t, std::size_t)>& body,
                 std::size_t min_items_per_thread) {
  const std::size_t useful = std::max<std::size_t>(1, count / std::max<std::size_t>(1, min_items_per_thread));
  const std::size_t parts = std::min<std::size_t>(static_cast<std::size_t>(std::max(threads, 1)), useful);
  if (parts <= 1) {
    if (count > 0) body(0, count);
    return;
  }
  RunWorkers(static_cast<int>(parts), [&](int worker, const std::atomic<bool>&) {
    const auto part = static_cast<std::size_t>(worker);
    body(count * part / parts, count * (part + 1) / parts);
  });
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
  RunWorkers(static_cast<int>(parts), [&](int, const std::atomic<bool>& stop) {
    for (std::size_t piece = next++; piece < pieces && !stop; piece = next++) {
      body(piece * grain, std::min(count, (piece + 1) * grain));
    }
  });
}

}  // namespace octocosm
