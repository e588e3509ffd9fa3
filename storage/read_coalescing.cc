#include "storage/read_coalescing.h"

#include <algorithm>

namespace octocosm {

std::vector<std::size_t> CoalesceAround(const BlockExtent& first, std::span<const BlockExtent> candidates,
                                        const CoalesceLimits& limits) {
  std::vector<std::size_t> order(candidates.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return candidates[a].offset < candidates[b].offset; });
  const auto begin_of = [&](std::size_t i) { return candidates[i].offset; };
  const auto end_of = [&](std::size_t i) { return candidates[i].offset + candidates[i].length; };

  std::uint64_t run_begin = first.offset;
  std::uint64_t run_end = first.offset + first.length;
  std::vector<std::size_t> right;
  // The first candidate that starts at or after the run's end.
  auto next = std::lower_bound(order.begin(), order.end(), run_end,
                               [&](std::size_t i, std::uint64_t at) { return begin_of(i) < at; });
  for (; next != order.end(); ++next) {
    if (begin_of(*next) < run_end) continue;  // overlaps the run: not a block of its own
    if (begin_of(*next) - run_end > limits.max_gap_bytes || end_of(*next) - run_begin > limits.max_span_bytes) break;
    run_end = end_of(*next);
    right.push_back(*next);
  }
  std::vector<std::size_t> left;
  // Backwards from the last candidate that starts before the run; it must
  // also end before it.
  auto previous = std::lower_bound(order.begin(), order.end(), run_begin,
                                   [&](std::size_t i, std::uint64_t at) { return begin_of(i) < at; });
  while (previous != order.begin()) {
    --previous;
    if (end_of(*previous) > run_begin) {
      continue;  // overlaps the run: not a block of its own
    }
    if (run_begin - end_of(*previous) > limits.max_gap_bytes || run_end - begin_of(*previous) > limits.max_span_bytes) {
      break;
    }
    run_begin = begin_of(*previous);
    left.push_back(*previous);
  }
  std::vector<std::size_t> run(left.rbegin(), left.rend());
  run.insert(run.end(), right.begin(), right.end());
  return run;
}

}  // namespace octocosm
