// Breaks the locking rules on purpose: the thread-safety check must reject
// it (tests/base/CMakeLists.txt, thread_safety_analysis_catches_violations).
// Never compiled into the build.
#include "base/mutex.h"

namespace octocosm {

class Counter {
 public:
  // Reads a guarded member without the lock.
  int Peek() const { return count_; }
  // Calls a helper that needs the lock without taking it.
  void Bump() { BumpLocked(); }
  // Writes a member while holding its lock shared only.
  void Reset() {
    ReaderLock lock(shared_);
    total_ = 0;
  }
  // Correct: no diagnostic.
  int Get() const {
    MutexLock lock(mutex_);
    return count_;
  }

 private:
  void BumpLocked() REQUIRES(mutex_) { ++count_; }

  mutable Mutex mutex_;
  SharedMutex shared_;
  int count_ GUARDED_BY(mutex_) = 0;
  int total_ GUARDED_BY(shared_) = 0;
};

}  // namespace octocosm
