// Runs a shell command line under timeout(1) and keeps its exit status and
// output, for tests that run the program as a user does.
#pragma once

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace octocosm::testing_support {

struct ProgramRun {
  int status = -1;     // exit status, or -1 when the shell did not exit normally
  std::string output;  // stdout and stderr
  int seconds = 0;     // its limit

  // For failure messages.
  std::string Describe() const {
    const std::string what = status == 124 ? "timed out after " + std::to_string(seconds) + " s"
                                           : "exit status " + std::to_string(status);
    return what + "; output:\n" + output;
  }
};

inline std::string ReadText(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// Runs `shell_command` (sh syntax; no single quotes in it) with `environment`
// (NAME=value ...) under timeout(1): at `seconds` its whole process group is
// sent SIGTERM, 10 s later SIGKILL, and the status is 124. The output goes
// through `log`, which is overwritten.
inline ProgramRun RunCommand(const std::string& shell_command, int seconds, const std::filesystem::path& log,
                             const std::string& environment = "") {
  const std::string line = environment + " timeout -k 10 " + std::to_string(seconds) + " sh -c '" + shell_command +
                           "' > " + log.string() + " 2>&1 < /dev/null";
  const int raw = std::system(line.c_str());
  ProgramRun run;
  run.status = raw != -1 && WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  run.output = ReadText(log);
  run.seconds = seconds;
  return run;
}

}  // namespace octocosm::testing_support
