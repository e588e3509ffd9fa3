#include "ingest/snapshot/isolated_process.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <fstream>
#include <string>
#include <vector>

#include "base/error.h"

extern char** environ;

namespace octocosm {
namespace {

// How IsolatedProcess tells the program it starts what to serve:
// "SERVICE:TIME_LIMIT_MS:EXTRA_ADDRESS_SPACE", removed from the environment
// before the service runs, so that a program it starts in turn is itself.
constexpr const char* kServiceVariable = "OCTOCOSM_ISOLATED_SERVICE";
// The service's end of the socket pair, in the started program.
constexpr int kServiceFd = 3;

// Both directions carry records: a tag byte, a little-endian u64 length,
// that many bytes. The owner sends requests; the service answers each with
// any number of notes, then one answer or exception. A service that dies
// mid-record leaves a torn last record, which its owner ignores.
constexpr char kRequest = 'Q';
constexpr char kNote = 'N';
constexpr char kAnswer = 'A';
constexpr char kException = 'E';
constexpr std::size_t kHeadBytes = 9;
// No answer is larger; a longer length is a service's memory gone wrong.
constexpr std::uint64_t kMaxRecordBytes = std::uint64_t{1} << 34;

// In a process serving (ServeIfStartedAs): its socket and the seconds of
// its own watchdog; -1 and 0 elsewhere. One thread serves, so plain
// variables suffice.
int g_service_fd = -1;
unsigned g_watchdog_seconds = 0;

// The program IsolatedProcess starts (SetIsolatedProgram).
std::string& IsolatedProgram() {
  static std::string program = "/proc/self/exe";
  return program;
}

// Sends all of `size` bytes, or gives up (the other side is gone). Never
// raises SIGPIPE.
bool SendAll(int fd, const char* data, std::size_t size) {
  while (size > 0) {
    const ssize_t n = send(fd, data, size, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    data += n;
    size -= static_cast<std::size_t>(n);
  }
  return true;
}

bool SendRecord(int fd, char tag, std::string_view bytes) {
  char head[kHeadBytes] = {tag};
  const std::uint64_t length = bytes.size();
  for (int i = 0; i < 8; ++i) head[1 + i] = static_cast<char>(length >> (8 * i));
  return SendAll(fd, head, sizeof head) && SendAll(fd, bytes.data(), bytes.size());
}

std::uint64_t RecordLength(const char* head) {
  std::uint64_t length = 0;
  for (int i = 0; i < 8; ++i) length |= static_cast<std::uint64_t>(static_cast<unsigned char>(head[1 + i])) << (8 * i);
  return length;
}

// The size of this process's address space in bytes (/proc/self/statm); 0
// when unknown.
std::uint64_t AddressSpaceBytes() {
  std::ifstream statm("/proc/self/statm");
  std::uint64_t pages = 0;
  if (!(statm >> pages)) return 0;
  return pages * static_cast<std::uint64_t>(sysconf(_SC_PAGESIZE));
}

// Blocking read of exactly `size` bytes in the service; false at the end of
// the stream (its owner is gone) or on an error.
bool ReceiveAll(int fd, char* data, std::size_t size) {
  while (size > 0) {
    const ssize_t n = recv(fd, data, size, 0);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    data += n;
    size -= static_cast<std::size_t>(n);
  }
  return true;
}

[[noreturn]] void Serve(IsolatedHandler handler) {
  for (;;) {
    char head[kHeadBytes];
    if (!ReceiveAll(g_service_fd, head, sizeof head)) _exit(0);  // the owner closed: done
    const std::uint64_t length = RecordLength(head);
    if (head[0] != kRequest || length > kMaxRecordBytes) _exit(124);
    std::string request(length, '\0');
    if (!ReceiveAll(g_service_fd, request.data(), request.size())) _exit(0);
    alarm(g_watchdog_seconds);
    char tag = kAnswer;
    std::string bytes;
    try {
      bytes = handler(request);
    } catch (const std::exception& e) {
      tag = kException;
      bytes = e.what();
    } catch (...) {
      tag = kException;
      bytes = "an exception that is not a std::exception";
    }
    alarm(0);
    // _exit, not exit: the service must not run the program's atexit
    // handlers or flush stdio buffers it never meant to write.
    if (!SendRecord(g_service_fd, tag, bytes)) _exit(126);
    if (tag == kException) _exit(0);
  }
}

std::string DescribeExit(int status) {
  if (WIFSIGNALED(status)) {
    const int signal_number = WTERMSIG(status);
    const char* name = strsignal(signal_number);
    return "was killed by signal " + std::to_string(signal_number) + (name ? " (" + std::string(name) + ")" : "");
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) != 0) return "exited with status " + std::to_string(WEXITSTATUS(status));
  return "exited without an answer";
}

std::string DescribeDuration(std::chrono::milliseconds duration) {
  const auto ms = duration.count();
  return ms % 1000 == 0 ? std::to_string(ms / 1000) + " s" : std::to_string(ms) + " ms";
}

}  // namespace

IsolatedProcess::IsolatedProcess(const char* service, const IsolationLimits& limits) : limits_(limits) {
  int ends[2];
  if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, ends) != 0) {
    throw Error(ErrorKind::kIo,
                std::string("cannot start a ") + service + " process: socketpair: " + std::strerror(errno));
  }
  // Above the descriptor the service's end becomes, so that moving it there
  // cannot overwrite the other.
  const int service_end = fcntl(ends[1], F_DUPFD_CLOEXEC, kServiceFd + 1);
  close(ends[1]);
  if (service_end < 0) {
    const int error = errno;
    close(ends[0]);
    throw Error(ErrorKind::kIo, std::string("cannot start a ") + service + " process: fcntl: " + std::strerror(error));
  }
  // Answers of a few MiB pass in fewer wake-ups with larger buffers; the
  // kernel caps what it grants.
  const int buffer_bytes = 4 << 20;
  setsockopt(ends[0], SOL_SOCKET, SO_RCVBUF, &buffer_bytes, sizeof buffer_bytes);
  setsockopt(service_end, SOL_SOCKET, SO_SNDBUF, &buffer_bytes, sizeof buffer_bytes);

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, service_end, kServiceFd);
  // Default dispositions and no blocked signals (this process may block or
  // catch some for its own cleanup), and a process group of its own, so that
  // a terminal's Ctrl-C reaches this process, which then ends it, and not
  // the service mid-request.
  posix_spawnattr_t attributes;
  posix_spawnattr_init(&attributes);
  sigset_t none, all;
  sigemptyset(&none);
  sigfillset(&all);
  posix_spawnattr_setsigmask(&attributes, &none);
  posix_spawnattr_setsigdefault(&attributes, &all);
  posix_spawnattr_setpgroup(&attributes, 0);
  posix_spawnattr_setflags(&attributes, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF | POSIX_SPAWN_SETPGROUP);

  std::vector<std::string> variables;
  for (char** variable = environ; variable != nullptr && *variable != nullptr; ++variable) {
    if (std::strncmp(*variable, kServiceVariable, std::strlen(kServiceVariable)) != 0)
      variables.emplace_back(*variable);
  }
  variables.push_back(std::string(kServiceVariable) + "=" + service + ":" + std::to_string(limits.time_limit.count()) +
                      ":" + std::to_string(limits.extra_address_space));
  std::vector<char*> environment;
  for (std::string& variable : variables) environment.push_back(variable.data());
  environment.push_back(nullptr);
  std::string name = std::string("octocosm ") + service;
  char* arguments[] = {name.data(), nullptr};

  const std::string& program = IsolatedProgram();
  const int error = posix_spawn(&pid_, program.c_str(), &actions, &attributes, arguments, environment.data());
  posix_spawnattr_destroy(&attributes);
  posix_spawn_file_actions_destroy(&actions);
  close(service_end);
  if (error != 0) {
    close(ends[0]);
    throw Error(ErrorKind::kIo, "cannot start " + program + " as the " + service + " process: " + std::strerror(error));
  }
  socket_ = ends[0];
}

IsolatedProcess::~IsolatedProcess() {
  // An idle service would exit at the closed socket; a busy one would not
  // notice until its request ends. It holds nothing worth saving.
  if (socket_ >= 0) close(socket_);
  if (failure_.empty()) {
    kill(pid_, SIGKILL);
    int status = 0;
    while (waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
  }
}

void IsolatedProcess::Fail(std::string failure) {
  failure_ = std::move(failure);
  close(socket_);
  socket_ = -1;
}

IsolatedResult IsolatedProcess::Call(std::string_view request) {
  Send(request);
  return Receive();
}

void IsolatedProcess::Send(std::string_view request) {
  // A send fails only when the service has gone; Receive says why.
  if (failure_.empty() && !send_failed_) send_failed_ = !SendRecord(socket_, kRequest, request);
}

IsolatedResult IsolatedProcess::Receive() {
  IsolatedResult result;
  if (!failure_.empty()) {
    result.failure = failure_;
    return result;
  }
  auto deadline = std::chrono::steady_clock::now() + limits_.time_limit;
  // The record being received: its head, then its body, each received into
  // place until `filled` reaches its size.
  std::string record(kHeadBytes, '\0');
  std::size_t filled = 0;
  bool in_body = false;
  char tag = 0;
  bool timed_out = false, malformed = false, ended = send_failed_;
  while (!ended) {
    if (filled < record.size()) {
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) {
        timed_out = true;
        break;
      }
      pollfd fd{socket_, POLLIN, 0};
      const int ready = poll(&fd, 1, static_cast<int>(std::min<long long>(left.count(), 1 << 30)));
      if (ready < 0 && errno == EINTR) continue;
      if (ready == 0) continue;  // the deadline is checked above
      const ssize_t n = recv(socket_, record.data() + filled, record.size() - filled, 0);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        ended = true;  // the service has exited or closed its end
        break;
      }
      filled += static_cast<std::size_t>(n);
      deadline = std::chrono::steady_clock::now() + limits_.time_limit;  // it is making progress
      if (filled < record.size()) continue;
    }
    if (!in_body) {
      tag = record[0];
      const std::uint64_t length = RecordLength(record.data());
      if (length > kMaxRecordBytes || (tag != kNote && tag != kAnswer && tag != kException)) {
        malformed = true;
        break;
      }
      record.assign(static_cast<std::size_t>(length), '\0');
      filled = 0;
      in_body = true;
      continue;
    }
    // A whole record.
    if (tag == kNote) {
      result.last_note = std::move(record);
      record.assign(kHeadBytes, '\0');
      filled = 0;
      in_body = false;
      continue;
    }
    if (tag == kAnswer) {
      result.returned = true;
      result.bytes = std::move(record);
      return result;
    }
    // An exception: the service exits after it.
    Fail("threw " + record);
    int status = 0;
    while (waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
    result.failure = failure_;
    return result;
  }
  if (timed_out || malformed) kill(pid_, SIGKILL);
  int status = 0;
  while (waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
  }
  if (timed_out) {
    Fail("went " + DescribeDuration(limits_.time_limit) + " without progress and was killed");
  } else if (malformed) {
    Fail("sent a malformed answer and was killed");
  } else {
    Fail(DescribeExit(status));
  }
  result.failure = failure_;
  return result;
}

bool ServeIfStartedAs(const char* service, IsolatedHandler handler) {
  const char* value = std::getenv(kServiceVariable);
  if (value == nullptr) return false;
  const std::string spec = value;
  const std::size_t first = spec.find(':');
  const std::size_t second = first == std::string::npos ? first : spec.find(':', first + 1);
  if (second == std::string::npos || spec.compare(0, first, service) != 0 || first != std::strlen(service)) {
    return false;
  }
  const long long time_limit_ms = std::atoll(spec.c_str() + first + 1);
  const unsigned long long extra_address_space = std::strtoull(spec.c_str() + second + 1, nullptr, 10);
  unsetenv(kServiceVariable);

  // A crash here is the expected failure of a damaged input, not worth a core file.
  const rlimit no_core{0, 0};
  setrlimit(RLIMIT_CORE, &no_core);
  if (extra_address_space > 0) {
    // Counted from this process's size: a sanitizer's shadow memory alone
    // maps terabytes, and an absolute cap would leave the service nothing.
    const std::uint64_t now = AddressSpaceBytes();
    if (now > 0) {
      const rlimit cap{now + extra_address_space, now + extra_address_space};
      setrlimit(RLIMIT_AS, &cap);
    }
  }
  g_watchdog_seconds = static_cast<unsigned>(std::max<long long>(1, (4 * time_limit_ms + 999) / 1000));
  g_service_fd = kServiceFd;
  Serve(handler);
}

void SetIsolatedProgram(const std::string& program) { IsolatedProgram() = program; }

void NoteIsolatedProgress(std::string_view note) {
  if (g_service_fd < 0) return;
  alarm(g_watchdog_seconds);
  SendRecord(g_service_fd, kNote, note);
}

}  // namespace octocosm
