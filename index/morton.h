// Node keys: an octree node named by its level and its cell, as one 64-bit
// number.
//
// A node at level L (root = 0, deepest = kMaxLevel = 21) covers cell (x, y, z)
// of a 2^L x 2^L x 2^L grid over the cube. Its key is a "locational code": the
// Morton code of the cell with a sentinel bit on top that records the level:
//
//   key = 1 << (3L)  |  interleave(x, y, z)
//
//   bit:   63 62 61 60 ... 5  4  3  2  1  0
//   level 21:  1 z20 y20 x20 ... z1 y1 x1 z0 y0 x0
//   level 1:   (zeros) ...   0  0  1 z0 y0 x0
//   root:      (zeros) ...               0  0  1
//
// so 21 levels use 63 bits plus the sentinel, and 0 is never a valid key.
// The octant of a child is its lowest three bits (x0 | y0 << 1 | z0 << 2);
// the parent is key >> 3, children are (key << 3) | octant.
//
// Two orders are useful:
//  - numeric order (operator<): level-major; all nodes of level L lie in
//    [2^(3L), 2^(3L+1)), in Morton (Z-curve) order inside a level. The store's
//    index is sorted this way, so the nodes of one level in a box are a few
//    contiguous key ranges (CoveringRanges).
//  - depth-first order (PreorderLess): a parent precedes its subtree and each
//    subtree is contiguous. Builders lay blocks out on disk this way for
//    locality.
//
// Reference: the bit-spreading follows F. Giesen, "Decoding Morton codes"
// (2009), as used in meshoptimizer's spatialorder.cpp.
#pragma once

#include <array>
#include <compare>
#include <cstdint>
#include <string>
#include <vector>

namespace octocosm {

inline constexpr int kMaxLevel = 21;

// Spreads the low 21 bits of v so that bit i lands at bit 3i.
constexpr std::uint64_t SpreadBits3(std::uint64_t v) {
  v &= 0x1fffff;                                   // ---- ---- ---- ---- ---- ---- ---- ---- ---- ---- ---- ---k jihg fedc ba98 7654 3210
  v = (v | (v << 32)) & 0x001f00000000ffffull;     // ---- ---- ---k jihg ---- ---- ---- ---- ---- ---- ---- ---- fedc ba98 7654 3210
  v = (v | (v << 16)) & 0x001f0000ff0000ffull;     // ---- ---- ---k jihg ---- ---- ---- ---- fedc ba98 ---- ---- ---- ---- 7654 3210
  v = (v | (v << 8)) & 0x100f00f00f00f00full;      // ---k ---- ---- jihg ---- ---- fedc ---- ---- ba98 ---- ---- 7654 ---- ---- 3210
  v = (v | (v << 4)) & 0x10c30c30c30c30c3ull;      // ---k ---- ji-- --hg ---- fe-- --dc ---- ba-- --98 ---- 76-- --54 ---- 32-- --10
  v = (v | (v << 2)) & 0x1249249249249249ull;      // ---k --j- -i-- h--g --f- -e-- d--c --b- -a-- 9--8 --7- -6-- 5--4 --3- -2-- 1--0
  return v;
}

// Inverse of SpreadBits3: gathers bits 0, 3, 6, ... into the low 21 bits.
constexpr std::uint64_t CompactBits3(std::uint64_t v) {
  v &= 0x1249249249249249ull;
  v = (v ^ (v >> 2)) & 0x10c30c30c30c30c3ull;
  v = (v ^ (v >> 4)) & 0x100f00f00f00f00full;
  v = (v ^ (v >> 8)) & 0x001f0000ff0000ffull;
  v = (v ^ (v >> 16)) & 0x001f00000000ffffull;
  v = (v ^ (v >> 32)) & 0x1fffff;
  return v;
}

struct CellCoord {
  std::uint32_t x = 0, y = 0, z = 0;
  friend bool operator==(const CellCoord&, const CellCoord&) = default;
};

// An inclusive box of cells at one level: lo <= cell <= hi on every axis.
struct CellBox {
  CellCoord lo, hi;
};

// An inclusive range of keys [first, last], all of the same level.
struct KeyRange {
  std::uint64_t first = 0, last = 0;
  friend bool operator==(const KeyRange&, const KeyRange&) = default;
};

class NodeKey {
 public:
  constexpr NodeKey() = default;  // the invalid key 0
  static constexpr NodeKey Root() { return NodeKey(1); }
  // The key's raw value; FromValue does not validate (use IsValid).
  static constexpr NodeKey FromValue(std::uint64_t value) { return NodeKey(value); }
  // Precondition: level <= kMaxLevel and every coordinate < 2^level.
  static constexpr NodeKey FromCell(int level, CellCoord cell) {
    return NodeKey((std::uint64_t{1} << (3 * level)) | SpreadBits3(cell.x) |
                   (SpreadBits3(cell.y) << 1) | (SpreadBits3(cell.z) << 2));
  }

  constexpr std::uint64_t value() const { return value_; }
  // A key is valid when its sentinel bit sits at a multiple of 3, at most 63.
  constexpr bool IsValid() const { return value_ != 0 && HighestBit(value_) % 3 == 0; }
  constexpr int level() const { return HighestBit(value_) / 3; }
  constexpr std::uint64_t morton() const { return value_ & ~(std::uint64_t{1} << (3 * level())); }
  constexpr CellCoord cell() const {
    const std::uint64_t m = morton();
    return {static_cast<std::uint32_t>(CompactBits3(m)), static_cast<std::uint32_t>(CompactBits3(m >> 1)),
            static_cast<std::uint32_t>(CompactBits3(m >> 2))};
  }

  // Precondition: not the root.
  constexpr NodeKey Parent() const { return NodeKey(value_ >> 3); }
  // Precondition: level() < kMaxLevel, octant < 8.
  constexpr NodeKey Child(int octant) const { return NodeKey((value_ << 3) | static_cast<std::uint64_t>(octant)); }
  // Which child of its parent this node is: x0 | y0 << 1 | z0 << 2.
  constexpr int OctantInParent() const { return static_cast<int>(value_ & 7); }
  // The ancestor at `ancestor_level` (<= level()).
  constexpr NodeKey AncestorAt(int ancestor_level) const { return NodeKey(value_ >> (3 * (level() - ancestor_level))); }
  constexpr bool IsAncestorOrSelf(NodeKey descendant) const {
    const int d = descendant.level() - level();
    return d >= 0 && (descendant.value_ >> (3 * d)) == value_;
  }
  // The keys at `descendant_level` (>= level()) below this node form one contiguous range.
  constexpr KeyRange DescendantRange(int descendant_level) const {
    const int d = 3 * (descendant_level - level());
    return {value_ << d, (value_ << d) | ((std::uint64_t{1} << d) - 1)};
  }

  // "r" followed by one octant digit per level, e.g. "r0172" (PotreeConverter's naming): readable in logs.
  std::string Path() const;
  // Parses Path() output; throws Error::InvalidArgument on malformed text.
  static NodeKey FromPath(const std::string& path);

  friend constexpr auto operator<=>(NodeKey, NodeKey) = default;

 private:
  explicit constexpr NodeKey(std::uint64_t value) : value_(value) {}
  static constexpr int HighestBit(std::uint64_t v) { return 63 - __builtin_clzll(v | 1); }

  std::uint64_t value_ = 0;
};

// Depth-first (pre-)order: a node precedes all of its descendants, and
// siblings' subtrees follow each other in octant order.
struct PreorderLess {
  constexpr bool operator()(NodeKey a, NodeKey b) const {
    const int la = a.level(), lb = b.level();
    const int common = la < lb ? la : lb;
    const NodeKey pa = a.AncestorAt(common), pb = b.AncestorAt(common);
    if (pa != pb) return pa < pb;
    return la < lb;
  }
};

// The smallest set of key ranges at `level` whose union is exactly the cells
// in `box` (clamped to the grid), in ascending order. When the exact cover
// needs more than `max_ranges` ranges, neighbouring ranges are merged (the
// smallest gaps first) so that the result covers a superset with at most
// `max_ranges` ranges; callers filter the extra nodes. max_ranges >= 1.
std::vector<KeyRange> CoveringRanges(int level, CellBox box, std::size_t max_ranges = SIZE_MAX);

}  // namespace octocosm
