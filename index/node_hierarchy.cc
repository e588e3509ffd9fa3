#include "index/node_hierarchy.h"

#include <algorithm>
#include <string>

#include "base/error.h"

namespace octocosm {

NodeHierarchy NodeHierarchy::Load(const Dataset& dataset, std::uint32_t epoch) {
  if (epoch >= dataset.epoch_count()) {
    throw Error::InvalidArgument("epoch " + std::to_string(epoch) + " is out of range: the store has " +
                                 std::to_string(dataset.epoch_count()) + " epoch(s)");
  }
  std::vector<IndexEntry> entries;
  entries.reserve(dataset.store().block_count(epoch));
  dataset.store().Scan(epoch, 0, ~std::uint64_t{0}, [&](const IndexEntry& e) {
    entries.push_back(e);
    return true;
  });
  return FromEntries(std::move(entries), dataset.store().page_file(epoch).path());
}

NodeHierarchy NodeHierarchy::FromEntries(std::vector<IndexEntry> entries, const std::string& where) {
  // Level-major key order puts every parent before its children.
  std::sort(entries.begin(), entries.end(), [](const IndexEntry& a, const IndexEntry& b) { return a.key < b.key; });
  NodeHierarchy h;
  h.nodes_.reserve(entries.size());
  for (const IndexEntry& e : entries) {
    const NodeKey key = NodeKey::FromValue(e.key);
    if (!key.IsValid()) throw Error::Corruption(where, "the index holds an invalid node key " + std::to_string(e.key));
    Node node;
    node.entry = e;
    node.key = key;
    const auto index = static_cast<std::int32_t>(h.nodes_.size());
    if (key.level() == 0) {
      if (index != 0) throw Error::Corruption(where, "the index holds two roots");
    } else {
      const std::optional<std::int32_t> parent = h.Find(key.Parent());
      if (!parent) throw Error::Corruption(where, "node " + key.Path() + " has no parent in the index");
      node.parent = *parent;
      h.nodes_[static_cast<std::size_t>(*parent)].children[static_cast<std::size_t>(key.OctantInParent())] = index;
    }
    h.nodes_.push_back(node);
  }
  if (!h.nodes_.empty() && h.nodes_[0].key.level() != 0) throw Error::Corruption(where, "the index has nodes but no root");
  for (const Node& n : h.nodes_) {
    if (n.is_leaf()) h.leaf_points_ += n.entry.point_count;
  }
  return h;
}

std::optional<std::int32_t> NodeHierarchy::Find(NodeKey key) const {
  // Nodes are sorted by key: a binary search needs no second table.
  const auto it = std::lower_bound(nodes_.begin(), nodes_.end(), key.value(),
                                   [](const Node& n, std::uint64_t k) { return n.key.value() < k; });
  if (it == nodes_.end() || it->key.value() != key.value()) return std::nullopt;
  return static_cast<std::int32_t>(it - nodes_.begin());
}

}  // namespace octocosm
