// The GLIBC_TUNABLES value `octocosm ingest` re-executes itself with
// (base/huge_pages.h): the huge-page tunable added to what is there, and
// nothing done when it is already set either way; and PreferSmallPages
// marking exactly the whole pages of a range, contents untouched.
#include <sys/mman.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "base/huge_pages.h"

namespace octocosm {
namespace {

TEST(HugePages, AddsTheTunableToWhatIsThere) {
  EXPECT_EQ(TunablesWithHugePages(nullptr), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(TunablesWithHugePages(""), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(TunablesWithHugePages("glibc.malloc.arena_max=2"), "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1");
  // A name that only starts like it is another tunable.
  EXPECT_EQ(TunablesWithHugePages("glibc.malloc.hugetlbx=3"), "glibc.malloc.hugetlbx=3:glibc.malloc.hugetlb=1");
}

TEST(HugePages, LeavesAChoiceAlreadyMadeAlone) {
  EXPECT_EQ(TunablesWithHugePages("glibc.malloc.hugetlb=0"), std::nullopt);
  EXPECT_EQ(TunablesWithHugePages("glibc.malloc.hugetlb=1"), std::nullopt);
  EXPECT_EQ(TunablesWithHugePages("glibc.malloc.arena_max=2:glibc.malloc.hugetlb=2"), std::nullopt);
}

// The VmFlags line of the mapping that holds `address` (/proc/self/smaps),
// empty where there is none.
std::string VmFlagsAt(const void* address) {
  std::ifstream smaps("/proc/self/smaps");
  const auto at = reinterpret_cast<std::uintptr_t>(address);
  bool inside = false;
  for (std::string line; std::getline(smaps, line);) {
    std::uintptr_t begin = 0, end = 0;
    char dash = 0;
    std::istringstream range(line);
    // A mapping's first line ("7f00-7f80 rw-p 00000000 00:00 0") has its
    // first colon after a space; its fields ("Size:   8 kB") before one.
    if (range >> std::hex >> begin >> dash >> end && dash == '-' && line.find(':') > line.find(' ')) {
      inside = begin <= at && at < end;
    } else if (inside && line.rfind("VmFlags:", 0) == 0) {
      return line;
    }
  }
  return {};
}

TEST(HugePages, PreferSmallPagesMarksTheWholePagesInsideTheRange) {
  const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  const std::size_t bytes = 1024 * page;
  void* mapped = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  ASSERT_NE(mapped, MAP_FAILED);
  auto* memory = static_cast<std::uint8_t*>(mapped);
  for (std::size_t i = 0; i < bytes; i += page / 2) memory[i] = static_cast<std::uint8_t>(i / (page / 2));

  EXPECT_FALSE(PreferSmallPages(nullptr, bytes));
  EXPECT_FALSE(PreferSmallPages(memory + 1, page));  // holds no whole page
  if (!PreferSmallPages(memory + 100, bytes - 200)) {
    ::munmap(mapped, bytes);
    GTEST_SKIP() << "the kernel has no transparent huge pages";
  }
  const std::string inner = VmFlagsAt(memory + page);
  const std::string first = VmFlagsAt(memory);  // partly outside the range: left alone
  if (inner.empty()) {
    ::munmap(mapped, bytes);
    GTEST_SKIP() << "no /proc/self/smaps";
  }
  EXPECT_NE(inner.find(" nh"), std::string::npos) << inner;
  EXPECT_EQ(first.find(" nh"), std::string::npos) << first;
  for (std::size_t i = 0; i < bytes; i += page / 2) {
    ASSERT_EQ(memory[i], static_cast<std::uint8_t>(i / (page / 2))) << i;
  }
  ::munmap(mapped, bytes);
}

}  // namespace
}  // namespace octocosm
