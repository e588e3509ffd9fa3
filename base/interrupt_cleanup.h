// Removal of temporary files and unfinished outputs when SIGINT, SIGTERM or
// SIGHUP ends the program. The program then dies of that signal as it would
// have without the removal, so a shell still sees status 128 + signal.
//
// A signal handler can run no destructors and may call only async-signal-safe
// functions, which rules out walking a directory tree. So these signals get
// no handler: InstallInterruptCleanup blocks them in every thread, and one
// thread of their own takes them with sigwait. That is an ordinary thread:
// it removes what is registered (newest first) with any code it likes, then
// restores the default action and raises the signal again.
//
// The other threads run on while it removes. A file one of them creates in the
// moment between the removal and the end can remain; temporary directories
// and unfinished stores carry locks that the owner's death releases
// (base/temp_directory.h, storage/store_writer.h), by which a later run
// recognises such remains, and those that kill -9 leaves, as abandoned.
#pragma once

#include <functional>

namespace octocosm {

// Call once, from main, before any other thread starts (threads inherit the
// blocked signals from their creator). A child process would inherit the
// blocked signals too: unblock them between fork and exec. If the signal
// thread cannot start, the signals keep their default action.
void InstallInterruptCleanup();

// While alive, `remove` runs if one of those signals arrives (on the signal
// thread, with no exception escaping). Registrations made without
// InstallInterruptCleanup (tests calling the library) never run.
class RemoveOnInterrupt {
 public:
  explicit RemoveOnInterrupt(std::function<void()> remove);
  // Waits while the signal thread is removing: the program is about to end,
  // and the caller must not go on to reuse what is being removed.
  ~RemoveOnInterrupt();
  RemoveOnInterrupt(const RemoveOnInterrupt&) = delete;
  RemoveOnInterrupt& operator=(const RemoveOnInterrupt&) = delete;

 private:
  unsigned long long id_;
};

}  // namespace octocosm
