// Reads that the one who asked for them may abandon while they wait on a
// server: a prefetch worker reading a block the renderer no longer wants.
//
// The worker installs the request's flag on its thread for the read's
// duration (ReadCancellationScope); a read from a server on that thread
// (storage/http_file.h) polls it while its transfer runs, and when it is set
// stops the transfer and throws kIo "cancelled", without retrying. Local
// reads do not poll: a pread is over before a cancellation would matter.
//
//   std::atomic<bool> cancelled{false};   // set from any thread
//   {
//     ReadCancellationScope scope(&cancelled);
//     source.ReadBlock(id);               // throws once `cancelled` is set
//   }
#pragma once

#include <atomic>

namespace octocosm {

class ReadCancellationScope {
 public:
  // `flag` must outlive the scope. Scopes nest; the innermost counts.
  explicit ReadCancellationScope(const std::atomic<bool>* flag);
  ~ReadCancellationScope();
  ReadCancellationScope(const ReadCancellationScope&) = delete;
  ReadCancellationScope& operator=(const ReadCancellationScope&) = delete;

 private:
  const std::atomic<bool>* outer_;
};

// Whether the read on this thread has been cancelled (false outside a scope).
bool ReadCancelled();

}  // namespace octocosm
