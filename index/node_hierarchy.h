// The octree of one epoch in memory: every node's index entry (key, point
// count, location of its block) and links to its parent and children, read
// with one scan of the block index and no block. A renderer walks it every
// frame instead of the index pages (a 10^8-point epoch has about 10^4 nodes:
// a few hundred kilobytes).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "index/dataset.h"
#include "index/morton.h"

namespace octocosm {

class NodeHierarchy {
 public:
  struct Node {
    IndexEntry entry;
    NodeKey key;
    std::int32_t parent = -1;
    std::array<std::int32_t, 8> children{-1, -1, -1, -1, -1, -1, -1, -1};  // by octant; -1: none
    bool is_leaf() const {
      for (std::int32_t c : children) {
        if (c >= 0) return false;
      }
      return true;
    }
  };

  // Reads every index entry of `epoch`. Throws Error (kCorruption) when the
  // entries do not form a tree: a node without its parent, or no root while
  // there are nodes.
  static NodeHierarchy Load(const Dataset& dataset, std::uint32_t epoch);
  // The same from entries in any order (tests, tools that already hold them).
  static NodeHierarchy FromEntries(std::vector<IndexEntry> entries, const std::string& where);

  // nodes()[0] is the root when the tree is not empty; parents come before
  // their children (level-major key order).
  const std::vector<Node>& nodes() const { return nodes_; }
  const Node& node(std::int32_t index) const { return nodes_[static_cast<std::size_t>(index)]; }
  bool empty() const { return nodes_.empty(); }
  std::uint64_t total_points_in_leaves() const { return leaf_points_; }
  std::optional<std::int32_t> Find(NodeKey key) const;

 private:
  std::vector<Node> nodes_;
  std::uint64_t leaf_points_ = 0;
};

}  // namespace octocosm
