// Runs a service in a separate process, so that a crash, a runaway
// allocation or an endless loop inside it ends that process and not this
// one. The HDF5 reader runs libhdf5 on a file's untrusted structure and data
// this way (docs/INPUT_FORMATS.md).
//
// The process is this program started again (/proc/self/exe, by
// posix_spawn, or the program SetIsolatedProgram names), not a fork() of
// this one: it inherits none of this
// process's memory or threads, so starting it costs the same however much
// this process holds, and it may be started from any thread. Before main()
// runs, a static initializer of the code that offers the service
// (ServeIfStartedAs) finds that it was started as that service, serves, and
// exits. A service is therefore offered by the same source file that starts
// it, so that any program that can start it can also be it.
//
// Requests are answered one at a time, in order; the service keeps its state
// (open files) between them. When the IsolatedProcess is destroyed, or its
// owner's process ends, the service sees its request pipe close and exits.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <string_view>

namespace octocosm {

struct IsolationLimits {
  // The process is killed (SIGKILL) when, answering a request, it sends
  // nothing, neither a note (NoteIsolatedProgress) nor its answer, for this
  // long: a limit on each step of a long request that notes its steps, on the
  // whole request otherwise. The service also ends itself when one request
  // goes four times this long without a note, should its owner no longer be
  // watching.
  std::chrono::milliseconds time_limit{30'000};
  // Address space the service may map beyond what it has when it starts to
  // serve (RLIMIT_AS); 0 = no cap. An allocation past it fails in the
  // service (std::bad_alloc, or NULL from malloc).
  std::uint64_t extra_address_space = std::uint64_t{1} << 30;
};

struct IsolatedResult {
  bool returned = false;  // the service answered: `bytes` is its answer
  std::string bytes;
  // When it did not: what became of the process, as a phrase that follows
  // "the process", e.g. "was killed by signal 11 (Segmentation fault)",
  // "went 30 s without progress and was killed", "threw std::bad_alloc".
  // Once a request has failed, every later one fails the same way.
  std::string failure;
  // The last note the service made (NoteIsolatedProgress) while answering
  // this request; empty when none.
  std::string last_note;
};

// A service's answer to one request. An exception it throws ends the
// service, and its what() is reported as the failure.
using IsolatedHandler = std::string (*)(std::string_view request);

class IsolatedProcess {
 public:
  // Starts this program again as `service` (ServeIfStartedAs). Throws
  // octocosm::Error (kind kIo) when it cannot be started.
  IsolatedProcess(const char* service, const IsolationLimits& limits = {});
  ~IsolatedProcess();
  IsolatedProcess(const IsolatedProcess&) = delete;
  IsolatedProcess& operator=(const IsolatedProcess&) = delete;

  // Sends `request` and waits for the answer, or for the process to fail.
  // Not for two threads at once.
  IsolatedResult Call(std::string_view request);
  // Call in two halves, so that the service can work on a request while
  // this process does something else: each Receive() takes the answer to
  // the oldest request sent and not yet received.
  void Send(std::string_view request);
  IsolatedResult Receive();

  pid_t pid() const { return pid_; }

 private:
  void Fail(std::string failure);

  IsolationLimits limits_;
  pid_t pid_ = -1;
  int socket_ = -1;      // this end of the socket pair
  std::string failure_;  // set once the process has failed
  bool send_failed_ = false;
};

// Makes IsolatedProcess start `program` instead of this program: for a
// process that embeds the library in a program of someone else's (the
// Python module), `program` being one of this project's that links the
// services it will start (the octocosm program). Call before starting any.
void SetIsolatedProgram(const std::string& program);

// For a static initializer in the file that offers `service`: when this
// process was started by IsolatedProcess(service), serves its requests with
// `handler` and exits without returning; otherwise returns false at once.
bool ServeIfStartedAs(const char* service, IsolatedHandler handler);

// Inside a handler run by ServeIfStartedAs: records `note` (e.g. the file it
// is about to read), so that if the process dies its owner learns how far it
// got, and starts its time limit afresh. Anywhere else it does nothing.
void NoteIsolatedProgress(std::string_view note);

}  // namespace octocosm
