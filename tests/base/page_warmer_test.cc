// PageWarmer (base/page_warmer.h): it faults in the whole pages of its
// ranges and never changes a byte, also while another thread fills them.
#include "base/page_warmer.h"

#include <gtest/gtest.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <memory>
#include <vector>

#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23
#endif

namespace octocosm {
namespace {

const std::size_t kPage = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));

// Fresh anonymous memory, unmapped at the end of the test.
struct Mapping {
  explicit Mapping(std::size_t size) : bytes(size) {
    void* p = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    base = p == MAP_FAILED ? nullptr : static_cast<std::uint8_t*>(p);
  }
  ~Mapping() {
    if (base != nullptr) munmap(base, bytes);
  }
  std::uint8_t* base;
  std::size_t bytes;
};

bool KernelPopulates() {
  Mapping probe(kPage);
  return probe.base != nullptr && madvise(probe.base, kPage, MADV_POPULATE_WRITE) == 0;
}

TEST(PageWarmer, FaultsInTheWholePagesOfItsRangesAndChangesNothing) {
  const std::size_t pages = 64;
  Mapping memory(pages * kPage);
  ASSERT_NE(memory.base, nullptr);
  // Bytes written before warming, in the partial pages at both ends and inside.
  const std::vector<std::size_t> marked = {0, 99, 100, 3 * kPage + 7, pages * kPage - 101, pages * kPage - 1};
  for (const std::size_t at : marked) memory.base[at] = static_cast<std::uint8_t>(at % 251 + 1);

  // A range that starts and ends inside a page: its whole pages are 1 .. pages - 2.
  PageWarmer warmer({{memory.base + 100, pages * kPage - 200}});
  warmer.Wait();

  for (std::size_t at = 0; at < pages * kPage; ++at) {
    const bool is_marked = std::find(marked.begin(), marked.end(), at) != marked.end();
    ASSERT_EQ(memory.base[at], is_marked ? static_cast<std::uint8_t>(at % 251 + 1) : 0) << "byte " << at;
  }
  if (!KernelPopulates()) GTEST_SKIP() << "this kernel has no MADV_POPULATE_WRITE; warming does nothing";
  EXPECT_EQ(warmer.warmed_bytes(), (pages - 2) * kPage);
}

TEST(PageWarmer, WarmsPagesThatNothingTouched) {
  if (!KernelPopulates()) GTEST_SKIP() << "this kernel has no MADV_POPULATE_WRITE; warming does nothing";
  const std::size_t pages = 256;
  Mapping memory(pages * kPage);
  ASSERT_NE(memory.base, nullptr);
  std::vector<unsigned char> resident(pages);
  ASSERT_EQ(mincore(memory.base, pages * kPage, resident.data()), 0);
  EXPECT_EQ(resident.front() & 1, 0) << "a fresh mapping should have no pages yet";
  PageWarmer warmer({{memory.base, pages * kPage}});
  warmer.Wait();
  ASSERT_EQ(mincore(memory.base, pages * kPage, resident.data()), 0);
  for (std::size_t page = 0; page < pages; ++page) EXPECT_EQ(resident[page] & 1, 1) << "page " << page;
}

TEST(PageWarmer, AFillerRacingItLosesNothing) {
  // Two ranges filled side by side, as the columns of a resident epoch are.
  const std::size_t count = std::size_t{8} << 20;
  std::unique_ptr<std::uint64_t[]> first(new std::uint64_t[count]);
  std::unique_ptr<std::uint32_t[]> second(new std::uint32_t[count]);
  {
    PageWarmer warmer({{first.get(), count * sizeof(std::uint64_t)}, {second.get(), count * sizeof(std::uint32_t)}});
    for (std::size_t i = 0; i < count; ++i) {  // the destructor stops the warmer wherever it is
      first[i] = i * 0x9e3779b97f4a7c15ull;
      second[i] = static_cast<std::uint32_t>(i ^ 0x5bd1e995u);
    }
  }
  for (std::size_t i = 0; i < count; ++i) {
    ASSERT_EQ(first[i], i * 0x9e3779b97f4a7c15ull) << "value " << i;
    ASSERT_EQ(second[i], static_cast<std::uint32_t>(i ^ 0x5bd1e995u)) << "value " << i;
  }
}

TEST(PageWarmer, RangesWithoutAWholePageAreLeftAlone) {
  Mapping memory(4 * kPage);
  ASSERT_NE(memory.base, nullptr);
  PageWarmer warmer({{memory.base + 1, kPage}, {memory.base + 2 * kPage, 0}, {memory.base + 3 * kPage + 5, 10}});
  warmer.Wait();
  warmer.Stop();  // after Wait, Stop has nothing to do
  EXPECT_EQ(warmer.warmed_bytes(), 0u);
  std::vector<unsigned char> resident(4);
  ASSERT_EQ(mincore(memory.base, 4 * kPage, resident.data()), 0);
  for (std::size_t page = 0; page < 4; ++page) EXPECT_EQ(resident[page] & 1, 0) << "page " << page;
}

}  // namespace
}  // namespace octocosm
