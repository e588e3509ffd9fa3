// Which waiting block reads join the read of another: blocks that lie close
// together in one file, read from a server with one request instead of one
// round trip each. The bytes between them come along and are dropped, so a
// gap is worth reading through only while it is small; and the first block
// of a read arrives only with the last, so a read stays short.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "storage/block_source.h"

namespace octocosm {

struct CoalesceLimits {
  // At 100 MB/s, 64 KiB take 0.6 ms: far less than a round trip of tens of ms.
  std::uint64_t max_gap_bytes = 64 << 10;
  // From the first byte of a read to its last; about 10 ms at 100 MB/s.
  std::uint64_t max_span_bytes = 1 << 20;
};

// The candidates that join a read of `first`: one run, in the file's order,
// in which no gap between neighbours exceeds max_gap_bytes and which spans
// at most max_span_bytes (first included). Grown to the right, then to the
// left. Returns their indices in `candidates`, in ascending order of offset.
// Candidates overlapping the run are left out.
std::vector<std::size_t> CoalesceAround(const BlockExtent& first, std::span<const BlockExtent> candidates,
                                        const CoalesceLimits& limits = {});

}  // namespace octocosm
