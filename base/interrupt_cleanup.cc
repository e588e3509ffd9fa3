#include "base/interrupt_cleanup.h"

#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cstring>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

#include "base/mutex.h"

namespace octocosm {
namespace {

struct Registry {
  Mutex mutex;
  unsigned long long next_id GUARDED_BY(mutex) = 0;
  std::vector<std::pair<unsigned long long, std::function<void()>>> removals GUARDED_BY(mutex);  // oldest first
};

Registry& TheRegistry() {
  static Registry* registry = new Registry;  // never destroyed: the signal thread may outlive main's statics
  return *registry;
}

sigset_t CleanupSignals() {
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGHUP);
  return signals;
}

[[noreturn]] void WaitForSignalThenCleanUp() {
  const sigset_t signals = CleanupSignals();
  int signal_number = 0;
  while (sigwait(&signals, &signal_number) != 0) {
  }
  Registry& registry = TheRegistry();
  // Held until the end: an owner that finishes meanwhile waits in its
  // destructor instead of going on with what is being removed.
  registry.mutex.Lock();
  const bool removing = !registry.removals.empty();
  if (removing) {
    const char* name = sigabbrev_np(signal_number);
    std::fprintf(stderr, "\noctocosm: interrupted by SIG%s: removing temporary files and unfinished outputs\n",
                 name ? name : "NAL");
  }
  for (auto it = registry.removals.rbegin(); it != registry.removals.rend(); ++it) {
    try {
      it->second();
    } catch (...) {
      // Removal is best effort: go on with the rest.
    }
  }
  // Die of the signal itself, so that the parent sees what killed us.
  std::signal(signal_number, SIG_DFL);
  sigset_t just_this;
  sigemptyset(&just_this);
  sigaddset(&just_this, signal_number);
  pthread_sigmask(SIG_UNBLOCK, &just_this, nullptr);
  raise(signal_number);
  _exit(128 + signal_number);  // not reached: the default action of these signals ends the process
}

}  // namespace

void InstallInterruptCleanup() {
  const sigset_t signals = CleanupSignals();
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  try {
    std::thread(WaitForSignalThenCleanUp).detach();
  } catch (const std::system_error&) {
    // No thread to take them (a process or memory limit): the signals keep
    // their default action, and end the program without the clean-up.
    pthread_sigmask(SIG_UNBLOCK, &signals, nullptr);
  }
}

RemoveOnInterrupt::RemoveOnInterrupt(std::function<void()> remove) {
  Registry& registry = TheRegistry();
  MutexLock lock(registry.mutex);
  id_ = registry.next_id++;
  registry.removals.emplace_back(id_, std::move(remove));
}

RemoveOnInterrupt::~RemoveOnInterrupt() {
  Registry& registry = TheRegistry();
  MutexLock lock(registry.mutex);
  for (auto it = registry.removals.begin(); it != registry.removals.end(); ++it) {
    if (it->first == id_) {
      registry.removals.erase(it);
      return;
    }
  }
}

}  // namespace octocosm
