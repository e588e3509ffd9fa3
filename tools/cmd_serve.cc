// `octocosm serve`: a directory of stores over HTTP, by nginx (Debian's
// nginx-light) run in the foreground with a configuration of its own, as
// docs/REMOTE.md serves one. Nothing of octocosm answers the requests.
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "base/interrupt_cleanup.h"
#include "base/temp_directory.h"
#include "tools/commands.h"

extern char** environ;

namespace octocosm {
namespace {

namespace fs = std::filesystem;

struct ServeFlags {
  std::string directory;
  std::string bind = "127.0.0.1";
  int port = 8080;
  std::string nginx;
};

std::string FindNginx(const std::string& given) {
  if (!given.empty()) return given;
  for (const char* candidate : {"/usr/sbin/nginx", "/usr/local/sbin/nginx", "/usr/bin/nginx"}) {
    if (::access(candidate, X_OK) == 0) return candidate;
  }
  throw Error::NotFound("nginx: serve runs nginx, which is not installed (Debian: apt-get install nginx-light)");
}

// Store directories (those holding a manifest.json) up to three levels
// below `root`, as paths relative to it.
std::vector<std::string> StoresBelow(const fs::path& root) {
  std::vector<std::string> stores;
  if (fs::exists(root / "manifest.json")) stores.push_back("");
  std::error_code error;
  for (fs::recursive_directory_iterator it(root, fs::directory_options::skip_permission_denied, error), end;
       !error && it != end; it.increment(error)) {
    if (it.depth() >= 3) it.disable_recursion_pending();
    std::error_code ignored;
    if (it->is_directory(ignored) && fs::exists(it->path() / "manifest.json", ignored)) {
      stores.push_back(fs::relative(it->path(), root).string());
      it.disable_recursion_pending();  // not the stores inside a store (its ID index)
    }
  }
  return stores;
}

void WriteConfiguration(const fs::path& file, const fs::path& work, const fs::path& root, const ServeFlags& f) {
  std::ofstream out(file);
  const std::string w = work.string();
  // Run as root, nginx's workers would become a user that may not read the
  // stores; they stay the user who runs serve.
  if (::geteuid() == 0) out << "user root;\n";
  out << "daemon off;\n"
      << "worker_processes auto;\n"
      << "pid " << w << "/nginx.pid;\n"
      << "error_log stderr;\n"
      << "events { worker_connections 1024; }\n"
      << "http {\n"
      << "  access_log off;\n"
      << "  client_body_temp_path " << w << "/client_body;\n"
      << "  proxy_temp_path " << w << "/proxy;\n"
      << "  fastcgi_temp_path " << w << "/fastcgi;\n"
      << "  uwsgi_temp_path " << w << "/uwsgi;\n"
      << "  scgi_temp_path " << w << "/scgi;\n"
      << "  sendfile on;\n"
      << "  tcp_nopush on;\n"
      << "  keepalive_requests 100000;\n"
      << "  server {\n"
      << "    listen " << f.bind << ":" << f.port << ";\n"
      << "    root " << root.string() << ";\n"
      << "  }\n"
      << "}\n";
  if (!out) throw Error::Io(file.string(), "cannot write nginx's configuration");
}

void Serve(const ServeFlags& f) {
  const fs::path root = fs::absolute(f.directory);
  if (!fs::is_directory(root)) throw Error::NotFound(f.directory + ": no such directory");
  const std::string nginx = FindNginx(f.nginx);
  TempDirectory work(fs::temp_directory_path().string(), "octocosm-serve");
  const fs::path config = fs::path(work.path()) / "nginx.conf";
  WriteConfiguration(config, work.path(), root, f);

  const std::string host = f.bind == "0.0.0.0" ? "HOST" : f.bind;
  const std::vector<std::string> stores = StoresBelow(root);
  std::printf("serving %s at http://%s:%d/ with %s (Ctrl-C stops it)\n", root.c_str(), host.c_str(), f.port,
              nginx.c_str());
  for (const std::string& store : stores) std::printf("  store: http://%s:%d/%s\n", host.c_str(), f.port, store.c_str());
  if (stores.empty()) std::printf("  (no store below it yet: a store is a directory holding manifest.json)\n");
  std::fflush(stdout);

  // nginx starts with the signals this program blocks for its clean-up
  // thread unblocked, and goes when a signal ends this program.
  posix_spawnattr_t attributes;
  posix_spawnattr_init(&attributes);
  sigset_t none;
  sigemptyset(&none);
  posix_spawnattr_setsigmask(&attributes, &none);
  posix_spawnattr_setflags(&attributes, POSIX_SPAWN_SETSIGMASK);
  std::vector<std::string> args = {nginx, "-p", work.path(), "-c", config.string(), "-e", "stderr"};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int error = posix_spawn(&pid, nginx.c_str(), nullptr, &attributes, argv.data(), environ);
  posix_spawnattr_destroy(&attributes);
  if (error != 0) throw Error::Io(nginx, std::string("cannot start it: ") + std::strerror(error));
  RemoveOnInterrupt stop_nginx([pid] {
    ::kill(pid, SIGQUIT);  // nginx's graceful stop
    int ignored = 0;
    ::waitpid(pid, &ignored, 0);
  });
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    throw Error::Io(nginx, "ended with status " + std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) +
                               " (its messages are above; is port " + std::to_string(f.port) + " in use?)");
  }
}

}  // namespace

void AddServeCommand(CLI::App& app) {
  auto flags = std::make_shared<ServeFlags>();
  CLI::App* cmd = app.add_subcommand(
      "serve",
      "Serve a directory of stores over HTTP for other machines' octocosm (view, render, query, ... take a store's\n"
      "URL): runs nginx (Debian's nginx-light) in the foreground with a configuration of its own, range requests\n"
      "and keep-alive on, until Ctrl-C. Any static HTTP server serves stores as well (docs/REMOTE.md).");
  cmd->add_option("directory", flags->directory, "the directory to serve (stores anywhere below it)")->required();
  cmd->add_option("--port", flags->port, "TCP port")->default_val(8080)->check(CLI::Range(1, 65535));
  cmd->add_option("--bind", flags->bind, "address to listen on (0.0.0.0: every interface)")->default_val("127.0.0.1");
  cmd->add_option("--nginx", flags->nginx, "the nginx program (default: /usr/sbin/nginx)");
  cmd->callback([flags] { Serve(*flags); });
}

}  // namespace octocosm
