#include "tests/tools/virtual_display.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <vector>

namespace octocosm::testing_support {
namespace {

std::string ReadLog(const std::filesystem::path& log) {
  std::ifstream in(log);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// Waits up to `seconds` for `pid` to end; whether it did.
bool Reap(pid_t pid, double seconds) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  for (;;) {
    const pid_t done = waitpid(pid, nullptr, WNOHANG);
    if (done == pid || (done < 0 && errno == ECHILD)) return true;
    if (std::chrono::steady_clock::now() > until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

}  // namespace

std::string VirtualDisplay::FindXvfb() {
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path ? path : "/usr/bin:/bin");
  for (std::string dir; std::getline(dirs, dir, ':');) {
    if (dir.empty()) continue;
    const std::filesystem::path candidate = std::filesystem::path(dir) / "Xvfb";
    if (access(candidate.c_str(), X_OK) == 0) return candidate.string();
  }
  return "";
}

VirtualDisplay::VirtualDisplay(const std::string& xvfb, const std::filesystem::path& log, double seconds) {
  int report[2];
  if (pipe(report) != 0) throw std::runtime_error("cannot make a pipe for Xvfb");
  // Everything the child needs, made before fork: after it, only system calls.
  const std::string report_fd = std::to_string(report[1]);
  std::vector<const char*> argv{xvfb.c_str(), "-displayfd", report_fd.c_str(), "-screen", "0", "1024x768x24",
                                "-nolisten",  "tcp",        "-noreset",        nullptr};
  const pid_t parent = getpid();
  pid_ = fork();
  if (pid_ < 0) {
    close(report[0]);
    close(report[1]);
    throw std::runtime_error("cannot fork to start Xvfb");
  }
  if (pid_ == 0) {
    prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (getppid() != parent) _exit(1);  // the test died before prctl
    close(report[0]);
    const int out = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int in = open("/dev/null", O_RDONLY);
    if (out < 0 || in < 0) _exit(126);
    dup2(in, 0);
    dup2(out, 1);
    dup2(out, 2);
    execv(argv[0], const_cast<char* const*>(argv.data()));
    _exit(127);
  }
  close(report[1]);

  // Xvfb writes the display number and a newline once it accepts clients.
  std::string number;
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  bool reported = false;
  while (!reported) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    pollfd fd{report[0], POLLIN, 0};
    const int ready = poll(&fd, 1, static_cast<int>(left.count()));
    if (ready < 0 && errno == EINTR) continue;
    if (ready <= 0) break;
    char c = 0;
    if (read(report[0], &c, 1) != 1) break;  // Xvfb ended without reporting
    if (c == '\n') {
      reported = !number.empty();
      if (!reported) break;
    } else {
      number += c;
    }
  }
  close(report[0]);
  if (!reported) {
    Stop();
    throw std::runtime_error("Xvfb did not start within " + std::to_string(seconds) + " s. Its output:\n" +
                             ReadLog(log));
  }
  name_ = ":" + number;
}

VirtualDisplay::~VirtualDisplay() { Stop(); }

void VirtualDisplay::Stop() {
  if (pid_ <= 0) return;
  kill(pid_, SIGTERM);
  if (!Reap(pid_, 10)) {
    kill(pid_, SIGKILL);
    Reap(pid_, 10);
  }
  pid_ = -1;
}

}  // namespace octocosm::testing_support
