#include "base/huge_pages.h"

#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>

namespace octocosm {

std::optional<std::string> TunablesWithHugePages(const char* current) {
  constexpr const char* kTunable = "glibc.malloc.hugetlb";
  const std::string tunables = current != nullptr ? current : "";
  // Tunables are name=value pairs separated by colons.
  std::size_t begin = 0;
  while (begin <= tunables.size()) {
    std::size_t end = tunables.find(':', begin);
    if (end == std::string::npos) end = tunables.size();
    const std::string pair = tunables.substr(begin, end - begin);
    if (pair.compare(0, std::strlen(kTunable) + 1, std::string(kTunable) + "=") == 0) return std::nullopt;
    begin = end + 1;
  }
  return tunables.empty() ? std::string(kTunable) + "=1" : tunables + ":" + kTunable + "=1";
}

void ReexecuteIngestWithHugePages(int argc, char** argv) {
  if (argc < 2 || std::strcmp(argv[1], "ingest") != 0) return;
  const std::optional<std::string> tunables = TunablesWithHugePages(std::getenv("GLIBC_TUNABLES"));
  if (!tunables) return;
  if (::setenv("GLIBC_TUNABLES", tunables->c_str(), 1) != 0) return;
  ::execv("/proc/self/exe", argv);
  // Still here: no /proc, say. Run on as we are; a child this process starts
  // keeps the tunable, harmlessly.
}

bool PreferSmallPages(void* begin, std::size_t bytes) {
  const auto page = static_cast<std::uintptr_t>(::sysconf(_SC_PAGESIZE));
  if (page == 0 || begin == nullptr) return false;
  const auto start = reinterpret_cast<std::uintptr_t>(begin);
  if (bytes > UINTPTR_MAX - start) return false;
  const std::uintptr_t first = (start + page - 1) / page * page;  // madvise wants whole pages
  const std::uintptr_t last = (start + bytes) / page * page;
  if (last <= first) return false;
  return ::madvise(reinterpret_cast<void*>(first), last - first, MADV_NOHUGEPAGE) == 0;
}

}  // namespace octocosm
