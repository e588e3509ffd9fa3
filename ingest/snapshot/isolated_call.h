// Runs a function in a child process made by fork() (no exec), so that a
// crash, a runaway allocation or an endless loop inside it ends the child
// and not this process. The HDF5 reader calls libhdf5 on a file's untrusted
// structure this way (docs/INPUT_FORMATS.md).
//
// The child is a copy of this process that runs only the calling thread
// (fork() copies no other thread). It is therefore safe only where no other
// thread holds a lock that the function needs: glibc makes malloc and stdio
// safe across fork(), but a library lock another thread holds at that moment
// stays held in the child, which then waits until the time limit kills it.
// Call it from the thread that owns whatever the function uses.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

namespace octocosm {

struct IsolationLimits {
  // The child is killed (SIGKILL) when it sends nothing, neither a note
  // (NoteIsolatedProgress) nor its result, for this long: a limit on each
  // step of a long call that notes its steps, on the whole call otherwise.
  std::chrono::milliseconds time_limit{30'000};
  // Address space the child may map beyond what it inherits (RLIMIT_AS,
  // counted from the parent's size at the fork); 0 = no cap. An allocation
  // past it fails in the child (std::bad_alloc, or NULL from malloc).
  std::uint64_t extra_address_space = std::uint64_t{1} << 30;
};

struct IsolatedResult {
  bool returned = false;  // the function returned in the child: `bytes` is what it returned
  std::string bytes;
  // When it did not: what became of the child, as a phrase that follows
  // "the child process", e.g. "was killed by signal 11 (Segmentation fault)",
  // "went 30 s without progress and was killed", "threw std::bad_alloc".
  std::string failure;
  // The last note the child made (NoteIsolatedProgress) before it ended;
  // empty when none.
  std::string last_note;
};

// Calls `function` in a child process and returns the bytes it returned, or
// why it did not return. An exception the function throws ends the child and
// is reported by its what(). Throws octocosm::Error (kind kIo) only when the
// child cannot be started (pipe or fork failing).
IsolatedResult CallIsolated(const std::function<std::string()>& function, const IsolationLimits& limits = {});

// Inside a function run by CallIsolated: records `note` (e.g. the file it is
// about to read), so that if the child dies the parent learns how far it got,
// and starts its time limit afresh. Anywhere else it does nothing.
void NoteIsolatedProgress(std::string_view note);

}  // namespace octocosm
