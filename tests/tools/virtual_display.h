// A virtual X display (Xvfb) of a test's own, for the viewer's tests.
//
// Xvfb picks a free display number itself and reports it (-displayfd), so
// tests running at the same time never race for a number, as concurrent
// `xvfb-run -a` can. The server ends with the object; if the test process
// dies first (killed by a ctest timeout), the kernel ends it too
// (PR_SET_PDEATHSIG), so no server outlives a run.
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <string>

namespace octocosm::testing_support {

class VirtualDisplay {
 public:
  // Xvfb's path on PATH, or empty when it is not installed.
  static std::string FindXvfb();

  // Starts `xvfb` (from FindXvfb) with one 1024x768x24 screen, its output in
  // `log`. Throws std::runtime_error, with that output, when the server has
  // not reported its display within `seconds`.
  VirtualDisplay(const std::string& xvfb, const std::filesystem::path& log, double seconds);
  ~VirtualDisplay();
  VirtualDisplay(const VirtualDisplay&) = delete;
  VirtualDisplay& operator=(const VirtualDisplay&) = delete;

  // For DISPLAY: ":N".
  const std::string& name() const { return name_; }

 private:
  void Stop();

  pid_t pid_ = -1;
  std::string name_;
};

}  // namespace octocosm::testing_support
