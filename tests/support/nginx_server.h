// An nginx (Debian's nginx-light) on 127.0.0.1 serving a directory, as a user
// serves a store (docs/REMOTE.md): started on a free port from a temporary
// configuration, in the foreground as a child process that the kernel stops
// if this process dies first (PR_SET_PDEATHSIG), stopped when the object
// dies. Under the served root, /norange/ ignores range requests (max_ranges
// 0) and /forbidden/ answers 403, for the tests of those faults.
#pragma once

#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "tests/support/program_run.h"  // ReadText

namespace octocosm::testing_support {

class NginxServer {
 public:
  // The nginx program, or "" when it is not installed: where Debian puts it,
  // else the first on PATH (a machine that has it only in a bundle of
  // programs, ../shared/gpu/bundle.sh).
  static std::string Program() {
    for (const char* candidate : {"/usr/sbin/nginx", "/usr/local/sbin/nginx", "/usr/bin/nginx"}) {
      if (::access(candidate, X_OK) == 0) return candidate;
    }
    const char* path = std::getenv("PATH");
    for (std::string rest = path != nullptr ? path : ""; !rest.empty();) {
      const std::size_t colon = rest.find(':');
      const std::string directory = rest.substr(0, colon);
      rest = colon == std::string::npos ? "" : rest.substr(colon + 1);
      const std::string candidate = directory + "/nginx";
      if (!directory.empty() && ::access(candidate.c_str(), X_OK) == 0) return candidate;
    }
    return "";
  }

  // Serves `root`; `work` holds the configuration, logs and pid file.
  // started() says whether it runs; error() why not.
  NginxServer(const std::filesystem::path& root, const std::filesystem::path& work) : work_(work) {
    const std::string program = Program();
    if (program.empty()) {
      error_ = "nginx is not installed (tools/bootstrap.sh installs nginx-light)";
      return;
    }
    std::filesystem::create_directories(work_);
    for (int attempt = 0; attempt < 5 && !started_; ++attempt) {
      port_ = FreePort();
      WriteConfiguration(root);
      pid_ = Start(program);
      started_ = pid_ > 0 && WaitUntilListening(port_);
      if (!started_) {
        Stop();
        error_ = "nginx did not start on port " + std::to_string(port_) + ": " + ReadText(work_ / "error.log");
      }
    }
  }

  ~NginxServer() { Stop(); }

  NginxServer(const NginxServer&) = delete;
  NginxServer& operator=(const NginxServer&) = delete;

  // A port on 127.0.0.1 that was free a moment ago.
  static int FreePort() {
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address);
    socklen_t length = sizeof address;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length);
    ::close(fd);
    return ntohs(address.sin_port);
  }

  // Whether something listens on 127.0.0.1:`port` within about 5 s.
  static bool WaitUntilListening(int port) {
    for (int i = 0; i < 500; ++i) {
      const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
      sockaddr_in address{};
      address.sin_family = AF_INET;
      address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      address.sin_port = htons(static_cast<std::uint16_t>(port));
      const bool connected = ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0;
      ::close(fd);
      if (connected) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  }

  bool started() const { return started_; }
  const std::string& error() const { return error_; }
  int port() const { return port_; }
  std::string Url(const std::string& path) const { return "http://127.0.0.1:" + std::to_string(port_) + path; }

 private:
  std::filesystem::path Config() const { return work_ / "nginx.conf"; }

  // nginx in the foreground (daemon off), as a child of this process.
  pid_t Start(const std::string& program) const {
    const std::string prefix = work_.string(), config = Config().string(), log = (work_ / "error.log").string();
    const pid_t parent = ::getpid();
    const pid_t pid = ::fork();
    if (pid != 0) return pid;
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(1);  // the parent died before prctl
    ::execl(program.c_str(), program.c_str(), "-p", prefix.c_str(), "-c", config.c_str(), "-e", log.c_str(),
            static_cast<char*>(nullptr));
    ::_exit(127);
  }

  // Stops nginx and waits for it, so that its port and files are free.
  void Stop() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGTERM);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
  }

  void WriteConfiguration(const std::filesystem::path& root) const {
    const std::string w = work_.string();
    std::ofstream out(Config());
    // Run as root, nginx's workers would switch to a user that may not read
    // the test's files; they stay the user who starts it.
    if (::geteuid() == 0) out << "user root;\n";
    out << "daemon off;\n"
        << "worker_processes 2;\n"
        << "pid " << w << "/nginx.pid;\n"
        << "error_log " << w << "/error.log;\n"
        << "events { worker_connections 256; }\n"
        << "http {\n"
        << "  access_log " << w << "/access.log;\n"
        << "  client_body_temp_path " << w << "/client_body;\n"
        << "  proxy_temp_path " << w << "/proxy;\n"
        << "  fastcgi_temp_path " << w << "/fastcgi;\n"
        << "  uwsgi_temp_path " << w << "/uwsgi;\n"
        << "  scgi_temp_path " << w << "/scgi;\n"
        << "  server {\n"
        << "    listen 127.0.0.1:" << port_ << ";\n"
        << "    root " << root.string() << ";\n"
        << "    location /norange/ { max_ranges 0; }\n"
        << "    location /forbidden/ { deny all; }\n"
        << "  }\n"
        << "}\n";
  }

  std::filesystem::path work_;
  pid_t pid_ = -1;
  int port_ = 0;
  bool started_ = false;
  std::string error_;
};

}  // namespace octocosm::testing_support
