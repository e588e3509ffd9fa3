// Transparent huge pages for the ingest's heap, through glibc's malloc.
//
// Ingest touches gigabytes of fresh memory (chunk buffers, node points,
// encoded blocks). With 4 KiB pages every first touch is a page fault: about
// 409,000 of them for 10^7 points, 44,000 with huge pages, and at 10^8 the
// ingest takes about a tenth less time with them (docs/BENCHMARKS.md). glibc's tunable
// `glibc.malloc.hugetlb=1` makes malloc advise the kernel to back its memory
// with 2 MiB transparent huge pages (where THP is set to "madvise", the
// common default), but glibc reads tunables only from the environment at
// program start. So the `ingest` subcommand re-executes the program once with
// the tunable added. A GLIBC_TUNABLES that already sets glibc.malloc.hugetlb
// (to 0, say) is left as it is.
//
// One exception: memory that is filled once and kept (a resident epoch's
// columns) is better on 4 KiB pages. On a virtual machine whose host backs
// guest memory lazily, a fresh huge page costs more per byte than fresh small
// pages (2.3-2.8 s per GiB against 0.5-1.4 s measured here), most likely
// because the guest kernel reports whole free 2 MiB blocks back to the host
// (free page reporting), which must then back them again, while small pages
// also come out of memory it still holds. What the build allocates and frees
// again stays on huge pages: there a page is reused, not fresh.
#pragma once

#include <cstddef>
#include <optional>
#include <string>

namespace octocosm {

// The GLIBC_TUNABLES value to run with: `current` (null when unset) plus
// glibc.malloc.hugetlb=1, or nullopt when `current` already sets it.
std::optional<std::string> TunablesWithHugePages(const char* current);

// For `octocosm ingest ...`: re-executes /proc/self/exe with the tunable set
// when it is not. Returns (doing nothing) for other subcommands, when the
// tunable is already set, or when the re-execution fails (the program then
// runs on with 4 KiB pages; only the speed differs).
void ReexecuteIngestWithHugePages(int argc, char** argv);

// Asks the kernel to back the whole pages inside [begin, begin + bytes) with
// 4 KiB pages (MADV_NOHUGEPAGE). Call it before the memory is first touched;
// pages already present stay as they are. Returns whether the kernel agreed
// (not where THP is absent); either way the memory's contents are untouched.
bool PreferSmallPages(void* begin, std::size_t bytes);

}  // namespace octocosm
