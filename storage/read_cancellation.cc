#include "storage/read_cancellation.h"

namespace octocosm {
namespace {

thread_local const std::atomic<bool>* current_flag = nullptr;

}  // namespace

ReadCancellationScope::ReadCancellationScope(const std::atomic<bool>* flag) : outer_(current_flag) {
  current_flag = flag;
}

ReadCancellationScope::~ReadCancellationScope() { current_flag = outer_; }

bool ReadCancelled() { return current_flag != nullptr && current_flag->load(std::memory_order_relaxed); }

}  // namespace octocosm
