#include "base/cancellation.h"

#include <atomic>

#include "base/error.h"

namespace octocosm {
namespace {
std::atomic<bool> cancellation_requested{false};
}  // namespace

void RequestCancellation() { cancellation_requested.store(true, std::memory_order_relaxed); }
void ClearCancellation() { cancellation_requested.store(false, std::memory_order_relaxed); }
bool CancellationRequested() { return cancellation_requested.load(std::memory_order_relaxed); }

void ThrowIfCancelled() {
  if (CancellationRequested()) throw Error(ErrorKind::kIo, "interrupted");
}

}  // namespace octocosm
