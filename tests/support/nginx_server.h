// An nginx (Debian's nginx-light) on 127.0.0.1 serving a directory, as a user
// serves a store (docs/REMOTE.md): started on a free port from a temporary
// configuration, stopped when the object dies. Under the served root,
// /norange/ ignores range requests (max_ranges 0) and /forbidden/ answers
// 403, for the tests of those faults.
#pragma once

#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "tests/support/program_run.h"

namespace octocosm::testing_support {

class NginxServer {
 public:
  // The nginx program, or "" when it is not installed.
  static std::string Program() {
    for (const char* candidate : {"/usr/sbin/nginx", "/usr/local/sbin/nginx", "/usr/bin/nginx"}) {
      if (::access(candidate, X_OK) == 0) return candidate;
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
      const ProgramRun run = RunCommand(program + " -p " + work_.string() + " -c " + Config().string() + " -e " +
                                            (work_ / "error.log").string(),
                                        30, work_ / "start.log");
      if (run.status != 0) {
        error_ = "nginx did not start: " + run.Describe() + ReadText(work_ / "error.log");
        continue;
      }
      started_ = WaitUntilListening();
      if (!started_) error_ = "nginx did not listen on port " + std::to_string(port_);
    }
  }

  ~NginxServer() {
    const std::string pid_text = ReadText(work_ / "nginx.pid");
    if (!pid_text.empty()) {
      const pid_t pid = static_cast<pid_t>(std::atoi(pid_text.c_str()));
      if (pid > 0 && ::kill(pid, SIGTERM) == 0) {
        // Wait for the master to go, so the port and files are free.
        for (int i = 0; i < 200 && ::kill(pid, 0) == 0; ++i) {
          std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
      }
    }
  }

  NginxServer(const NginxServer&) = delete;
  NginxServer& operator=(const NginxServer&) = delete;

  bool started() const { return started_; }
  const std::string& error() const { return error_; }
  int port() const { return port_; }
  std::string Url(const std::string& path) const { return "http://127.0.0.1:" + std::to_string(port_) + path; }

 private:
  std::filesystem::path Config() const { return work_ / "nginx.conf"; }

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

  bool WaitUntilListening() const {
    for (int i = 0; i < 500; ++i) {
      const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
      sockaddr_in address{};
      address.sin_family = AF_INET;
      address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      address.sin_port = htons(static_cast<std::uint16_t>(port_));
      const bool connected = ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0;
      ::close(fd);
      if (connected) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  }

  void WriteConfiguration(const std::filesystem::path& root) const {
    const std::string w = work_.string();
    std::ofstream out(Config());
    // Run as root, nginx's workers would switch to a user that may not read
    // the test's files; they stay the user who starts it.
    if (::geteuid() == 0) out << "user root;\n";
    out << "worker_processes 2;\n"
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
  int port_ = 0;
  bool started_ = false;
  std::string error_;
};

}  // namespace octocosm::testing_support
