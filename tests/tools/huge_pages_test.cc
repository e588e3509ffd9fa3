// The GLIBC_TUNABLES value `octocosm ingest` re-executes itself with
// (tools/huge_pages.h): the huge-page tunable added to what is there, and
// nothing done when it is already set either way.
#include <gtest/gtest.h>

#include "tools/huge_pages.h"

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

}  // namespace
}  // namespace octocosm
