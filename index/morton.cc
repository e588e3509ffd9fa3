#include "index/morton.h"

#include <algorithm>
#include <functional>

#include "base/error.h"

namespace octocosm {

std::string NodeKey::Path() const {
  const int l = level();
  std::string path(static_cast<std::size_t>(l) + 1, 'r');
  for (int i = l; i >= 1; --i) {
    path[static_cast<std::size_t>(i)] = static_cast<char>('0' + ((value_ >> (3 * (l - i))) & 7));
  }
  return path;
}

NodeKey NodeKey::FromPath(const std::string& path) {
  if (path.empty() || path[0] != 'r' || path.size() > kMaxLevel + 1) {
    throw Error::InvalidArgument("node path '" + path + "': expected 'r' followed by at most " +
                                 std::to_string(kMaxLevel) + " octant digits 0-7");
  }
  NodeKey key = Root();
  for (std::size_t i = 1; i < path.size(); ++i) {
    if (path[i] < '0' || path[i] > '7') {
      throw Error::InvalidArgument("node path '" + path + "': '" + path[i] + "' is not an octant digit 0-7");
    }
    key = key.Child(path[i] - '0');
  }
  return key;
}

std::vector<KeyRange> CoveringRanges(int level, CellBox box, std::size_t max_ranges) {
  if (level < 0 || level > kMaxLevel) {
    throw Error::InvalidArgument("level " + std::to_string(level) + " outside 0.." + std::to_string(kMaxLevel));
  }
  if (max_ranges == 0) throw Error::InvalidArgument("CoveringRanges: max_ranges must be at least 1");
  const std::uint32_t grid_max = (std::uint32_t{1} << level) - 1;
  auto clamp_axis = [&](std::uint32_t& lo, std::uint32_t& hi) {
    hi = std::min(hi, grid_max);
    return lo <= hi;
  };
  std::vector<KeyRange> ranges;
  if (!clamp_axis(box.lo.x, box.hi.x) || !clamp_axis(box.lo.y, box.hi.y) || !clamp_axis(box.lo.z, box.hi.z)) {
    return ranges;
  }

  // Descend from the root: a node wholly inside the box contributes its whole
  // descendant range at `level`, a node outside nothing, a straddling node
  // recurses. Children are visited in octant order, so ranges come out sorted.
  std::function<void(NodeKey)> visit = [&](NodeKey node) {
    const int shift = level - node.level();
    const CellCoord c = node.cell();
    const std::uint32_t x0 = c.x << shift, y0 = c.y << shift, z0 = c.z << shift;
    const std::uint32_t span = (std::uint32_t{1} << shift) - 1;
    const std::uint32_t x1 = x0 + span, y1 = y0 + span, z1 = z0 + span;
    if (x1 < box.lo.x || x0 > box.hi.x || y1 < box.lo.y || y0 > box.hi.y || z1 < box.lo.z || z0 > box.hi.z) return;
    const bool inside = x0 >= box.lo.x && x1 <= box.hi.x && y0 >= box.lo.y && y1 <= box.hi.y &&
                        z0 >= box.lo.z && z1 <= box.hi.z;
    if (inside || shift == 0) {
      const KeyRange r = node.DescendantRange(level);
      if (!ranges.empty() && ranges.back().last + 1 == r.first) {
        ranges.back().last = r.last;
      } else {
        ranges.push_back(r);
      }
      return;
    }
    for (int octant = 0; octant < 8; ++octant) visit(node.Child(octant));
  };
  visit(NodeKey::Root());

  if (ranges.size() > max_ranges) {
    // Merge across the smallest gaps: keep the (max_ranges - 1) largest gaps.
    std::vector<std::pair<std::uint64_t, std::size_t>> gaps;  // (gap size, index of range before it)
    gaps.reserve(ranges.size() - 1);
    for (std::size_t i = 0; i + 1 < ranges.size(); ++i) gaps.emplace_back(ranges[i + 1].first - ranges[i].last, i);
    std::nth_element(gaps.begin(), gaps.begin() + static_cast<std::ptrdiff_t>(max_ranges - 1), gaps.end(),
                     [](const auto& a, const auto& b) { return a.first > b.first; });
    std::vector<bool> split_after(ranges.size(), false);
    for (std::size_t g = 0; g + 1 < max_ranges; ++g) split_after[gaps[g].second] = true;
    std::vector<KeyRange> merged;
    merged.reserve(max_ranges);
    KeyRange current = ranges[0];
    for (std::size_t i = 0; i + 1 < ranges.size(); ++i) {
      if (split_after[i]) {
        merged.push_back(current);
        current = ranges[i + 1];
      } else {
        current.last = ranges[i + 1].last;
      }
    }
    merged.push_back(current);
    ranges = std::move(merged);
  }
  return ranges;
}

}  // namespace octocosm
