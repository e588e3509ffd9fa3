// Loops over [0, count) on several threads, the calling thread among them.
// An exception thrown by a body is rethrown on the calling thread after the
// other threads finish.
#pragma once

#include <atomic>
#include <cstddef>
#include <functional>

namespace octocosm {

// Splits [0, count) into one contiguous range per thread and runs
// body(begin, end) on each, the calling thread taking the first range. The
// split depends only on count and threads, so a body whose ranges do not
// interact gives the same result for any thread count, and a body may keep
// state per range (the counting sort's tables). min_items_per_thread keeps
// light loops on fewer threads, where starting a thread would cost more than
// it saves.
void ParallelFor(std::size_t count, int threads, const std::function<void(std::size_t, std::size_t)>& body,
                 std::size_t min_items_per_thread = 4096);

// Runs body(begin, end) over [0, count) in pieces of `grain` items (the last
// one shorter) that `threads` threads take in turn as they finish their last.
// For loops whose items are independent but whose threads run unevenly: on a
// shared machine a thread that is descheduled, or stops to fault in fresh
// pages, holds up a static split by the whole delay, a dynamic one by at most
// one piece. Once a piece's error has left `body`, no thread takes another
// piece (pieces already running finish), and the error is rethrown on the
// calling thread.
void ParallelForDynamic(std::size_t count, int threads, std::size_t grain,
                        const std::function<void(std::size_t, std::size_t)>& body);

// Runs work(worker, stop) on `threads` threads (at least one), worker 0 on
// the calling thread, and returns when all have returned. The first
// exception to leave `work` sets `stop` and is rethrown here afterwards: a
// worker that takes items in turn checks `stop` before taking the next, so
// the others give up soon after one fails. The loops above, and any that
// takes its items in an order of its own, run on this.
void RunWorkers(int threads, const std::function<void(int worker, const std::atomic<bool>& stop)>& work);

// The thread count to use for `requested` (0 means one per core this process
// may run on, CoresAllowed).
int ResolveThreadCount(int requested);

// The cores this process may run on (its CPU affinity: taskset, a cgroup's
// cpuset, or mpirun's binding of a rank), at least 1. Threads beyond them
// only take turns.
unsigned CoresAllowed();

}  // namespace octocosm
