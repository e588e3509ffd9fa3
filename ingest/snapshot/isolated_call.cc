#include "ingest/snapshot/isolated_call.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <exception>
#include <fstream>
#include <string>

#include "base/error.h"

namespace octocosm {
namespace {

// The child writes records to the pipe: a tag byte, a little-endian u32
// length, that many bytes. Notes come first, then exactly one result or
// exception record, then the child exits. A child that dies mid-record
// leaves a torn last record, which the parent ignores.
constexpr char kNote = 'N';
constexpr char kResult = 'R';
constexpr char kException = 'E';

// The write end of the pipe in a child of CallIsolated; -1 elsewhere. The
// child runs one thread, so a plain variable suffices.
int g_child_pipe = -1;

// Writes all of `size` bytes, or gives up (the parent is gone).
bool WriteAll(int fd, const char* data, std::size_t size) {
  while (size > 0) {
    const ssize_t n = write(fd, data, size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    data += n;
    size -= static_cast<std::size_t>(n);
  }
  return true;
}

bool WriteRecord(int fd, char tag, std::string_view bytes) {
  const auto length = static_cast<std::uint32_t>(bytes.size());
  const char head[5] = {tag, static_cast<char>(length), static_cast<char>(length >> 8), static_cast<char>(length >> 16),
                        static_cast<char>(length >> 24)};
  return WriteAll(fd, head, sizeof head) && WriteAll(fd, bytes.data(), bytes.size());
}

// The size of this process's address space in bytes (/proc/self/statm); 0
// when unknown.
std::uint64_t AddressSpaceBytes() {
  std::ifstream statm("/proc/self/statm");
  std::uint64_t pages = 0;
  if (!(statm >> pages)) return 0;
  return pages * static_cast<std::uint64_t>(sysconf(_SC_PAGESIZE));
}

// In the child, after fork(): limits, the call, its result, _exit. _exit and
// not exit: the child must not run the parent's atexit handlers or flush its
// stdio buffers, which would repeat the parent's output.
[[noreturn]] void RunChild(const std::function<std::string()>& function, int pipe_write, pid_t parent,
                           std::uint64_t address_space_cap) {
  // Die with the parent, rather than run on unwatched when it is killed.
  prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (getppid() != parent) _exit(125);
  // A crash here is the expected failure of a damaged input, not worth a core file.
  const rlimit no_core{0, 0};
  setrlimit(RLIMIT_CORE, &no_core);
  if (address_space_cap > 0) {
    const rlimit cap{address_space_cap, address_space_cap};
    setrlimit(RLIMIT_AS, &cap);
  }
  g_child_pipe = pipe_write;
  char tag = kResult;
  std::string bytes;
  try {
    bytes = function();
  } catch (const std::exception& e) {
    tag = kException;
    bytes = e.what();
  } catch (...) {
    tag = kException;
    bytes = "an exception that is not a std::exception";
  }
  _exit(WriteRecord(pipe_write, tag, bytes) ? 0 : 126);
}

// Reads the child's records, ends the child when it sends nothing for
// `time_limit` and reaps it. Returns the result with `failure` set unless the
// child returned.
IsolatedResult ReadChild(pid_t child, int pipe_read, std::chrono::milliseconds time_limit) {
  auto deadline = std::chrono::steady_clock::now() + time_limit;
  std::string stream;
  bool timed_out = false;
  for (;;) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      timed_out = true;
      break;
    }
    pollfd fd{pipe_read, POLLIN, 0};
    const int ready = poll(&fd, 1, static_cast<int>(std::min<long long>(left.count(), 1 << 30)));
    if (ready < 0 && errno == EINTR) continue;
    if (ready == 0) continue;  // the deadline is checked above
    char buffer[1 << 16];
    const ssize_t n = read(pipe_read, buffer, sizeof buffer);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;  // end of file: the child has exited or closed the pipe
    stream.append(buffer, static_cast<std::size_t>(n));
    deadline = std::chrono::steady_clock::now() + time_limit;  // it is making progress
  }
  if (timed_out) kill(child, SIGKILL);
  int status = 0;
  while (waitpid(child, &status, 0) < 0 && errno == EINTR) {
  }

  IsolatedResult result;
  std::size_t at = 0;
  char final_tag = 0;
  std::string final_bytes;
  while (stream.size() - at >= 5) {
    const auto* head = reinterpret_cast<const unsigned char*>(stream.data() + at);
    const std::uint32_t length = head[1] | head[2] << 8 | head[3] << 16 | static_cast<std::uint32_t>(head[4]) << 24;
    if (stream.size() - at - 5 < length) break;  // torn
    std::string bytes = stream.substr(at + 5, length);
    if (stream[at] == kNote) {
      result.last_note = std::move(bytes);
    } else {
      final_tag = stream[at];
      final_bytes = std::move(bytes);
    }
    at += 5 + length;
  }

  if (timed_out) {
    const auto ms = time_limit.count();
    result.failure = "went " +
                     (ms % 1000 == 0 ? std::to_string(ms / 1000) + " s" : std::to_string(ms) + " ms") +
                     " without progress and was killed";
  } else if (WIFSIGNALED(status)) {
    const int signal_number = WTERMSIG(status);
    const char* name = strsignal(signal_number);
    result.failure =
        "was killed by signal " + std::to_string(signal_number) + (name ? " (" + std::string(name) + ")" : "");
  } else if (WIFEXITED(status) && WEXITSTATUS(status) != 0) {
    result.failure = "exited with status " + std::to_string(WEXITSTATUS(status));
  } else if (final_tag == kException) {
    result.failure = "threw " + final_bytes;
  } else if (final_tag != kResult) {
    result.failure = "exited without a result";
  } else {
    result.returned = true;
    result.bytes = std::move(final_bytes);
  }
  return result;
}

}  // namespace

IsolatedResult CallIsolated(const std::function<std::string()>& function, const IsolationLimits& limits) {
  std::uint64_t cap = 0;
  if (limits.extra_address_space > 0) {
    // Counted from this process's size: a sanitizer's shadow memory alone
    // maps terabytes, and an absolute cap would leave the child nothing.
    const std::uint64_t now = AddressSpaceBytes();
    if (now > 0) cap = now + limits.extra_address_space;
  }
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0) {
    throw Error(ErrorKind::kIo, std::string("cannot start a child process: pipe: ") + std::strerror(errno));
  }
  const pid_t parent = getpid();
  const pid_t child = fork();
  if (child < 0) {
    const int error = errno;
    close(fds[0]);
    close(fds[1]);
    throw Error(ErrorKind::kIo, std::string("cannot start a child process: fork: ") + std::strerror(error));
  }
  if (child == 0) {
    close(fds[0]);
    RunChild(function, fds[1], parent, cap);
  }
  close(fds[1]);
  IsolatedResult result = ReadChild(child, fds[0], limits.time_limit);
  close(fds[0]);
  return result;
}

void NoteIsolatedProgress(std::string_view note) {
  if (g_child_pipe >= 0) WriteRecord(g_child_pipe, kNote, note);
}

}  // namespace octocosm
