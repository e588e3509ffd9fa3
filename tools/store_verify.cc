// octocosm verify: every checksum and structural invariant of a dataset store.
#include "tools/store_verify.h"

#include <algorithm>
#include <bitset>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "index/block_codec.h"
#include "index/dataset.h"
#include "index/id_index.h"
#include "storage/error.h"

namespace octocosm {
namespace {

// Collects faults instead of stopping at the first, so one run reports all damage.
class FaultLog {
 public:
  FaultLog(VerifyReport& report, const std::function<void(const std::string&)>& on_fault)
      : report_(report), on_fault_(on_fault) {}
  void Add(const std::string& message) {
    if (report_.faults.size() < kMaxFaultsKept) report_.faults.push_back(message);
    if (on_fault_) on_fault_(message);
  }

 private:
  static constexpr std::size_t kMaxFaultsKept = 1000;
  VerifyReport& report_;
  const std::function<void(const std::string&)>& on_fault_;
};

void VerifyEpoch(const Dataset& dataset, std::uint32_t e, const IdIndexReader* ids, FaultLog& faults,
                 std::uint64_t& blocks_checked) {
  const StoreReader& store = dataset.store();
  const Cube& cube = dataset.cube(e);
  std::vector<IndexEntry> entries;
  store.Scan(e, 0, ~std::uint64_t{0}, [&](const IndexEntry& entry) {
    entries.push_back(entry);
    return true;
  });
  std::unordered_map<std::uint64_t, double> node_mass;      // sum of a node's own weights
  std::unordered_map<std::uint64_t, double> children_mass;  // sum of its children's node masses
  std::unordered_set<std::uint64_t> present, has_children;
  std::uint64_t leaf_points = 0;
  std::vector<std::pair<std::uint64_t, NodeKey>> id_samples;
  std::mt19937_64 rng(e);
  const ColumnSet declared = dataset.columns(e);
  // Inner nodes of clusters carry these besides; whether a node's points are
  // clusters follows from its children's particle types (below).
  const ColumnSet cluster_columns = dataset.cluster_columns();
  std::unordered_map<std::uint64_t, std::bitset<256>> children_types;  // of every node with children
  std::unordered_map<std::uint64_t, bool> carries_cluster_columns;      // of every inner node
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const NodeKey key = NodeKey::FromValue(entries[i].key);
    if (!key.IsValid()) {
      faults.Add("epoch " + std::to_string(e) + ": invalid node key 0x" + std::to_string(entries[i].key));
      continue;
    }
    present.insert(entries[i].key);
    if (key.level() > 0) has_children.insert(key.Parent().value());
  }
  for (const IndexEntry& entry : entries) {
    const NodeKey key = NodeKey::FromValue(entry.key);
    if (!key.IsValid()) continue;
    const std::string where = dataset.Where(e, key);
    try {
      const Bytes bytes = store.ReadBlock({e, entry.key});
      const DecodedBlock block = DecodeBlock(bytes, kAllColumns, key, cube, where);
      ++blocks_checked;
      const std::size_t n = block.header.point_count;
      if (n != entry.point_count) {
        faults.Add(where + ": index says " + std::to_string(entry.point_count) + " points, block holds " + std::to_string(n));
      }
      ColumnSet carried = 0;
      for (const BlockColumn& column : block.header.columns) carried |= ColumnBit(column.id);
      const bool leaf = !has_children.count(entry.key);
      // An inner node may carry the cluster columns as well; which inner
      // nodes must is checked once all their children are read.
      const bool with_cluster_columns = !leaf && cluster_columns != 0 && carried == (declared | cluster_columns);
      if (carried != declared && !with_cluster_columns) {
        faults.Add(where + ": carries the columns " + ColumnNames(carried) + ", the manifest declares " +
                   ColumnNames(declared) +
                   (cluster_columns != 0 ? (leaf ? " for a leaf" : " (and " + ColumnNames(cluster_columns) + " for clusters)")
                                         : ""));
      }
      if (!leaf) carries_cluster_columns[entry.key] = with_cluster_columns;
      if (key.level() > 0 && cluster_columns != 0) {
        std::bitset<256>& types = children_types[key.Parent().value()];
        for (const std::uint8_t t : block.points.type) types.set(t);
      }
      if (n > dataset.capacity() && !(leaf && key.level() == dataset.max_level())) {
        faults.Add(where + ": " + std::to_string(n) + " points exceed the node capacity " + std::to_string(dataset.capacity()));
      }
      if (key.level() > 0 && !present.count(key.Parent().value())) {
        faults.Add(where + ": its parent " + key.Parent().Path() + " is missing");
      }
      double mass = 0;
      for (double w : block.points.weight) mass += w;
      node_mass[entry.key] = mass;
      if (key.level() > 0) children_mass[key.Parent().value()] += mass;
      if (leaf) {
        leaf_points += n;
        for (std::size_t p = 0; p < block.points.id.size(); ++p) {
          if (id_samples.size() < 1000) id_samples.emplace_back(block.points.id[p], key);
          else if (rng() % 64 == 0) id_samples[rng() % id_samples.size()] = {block.points.id[p], key};
        }
      }
    } catch (const Error& error) {
      faults.Add(error.what());
    }
  }
  // A node's points are clusters exactly when the builder could give every
  // child octant and particle type of its population a cluster of its own
  // (index/subtree_builder.cc, AggregateParent); otherwise they are a sample.
  for (const auto& [key, carries] : carries_cluster_columns) {
    const auto types = children_types.find(key);
    if (types == children_types.end()) continue;  // no child was read: faulted above
    const std::size_t type_count = std::max<std::size_t>(1, types->second.count());
    const bool clusters = dataset.capacity() >= 8 * type_count;
    if (carries != clusters) {
      faults.Add(dataset.Where(e, NodeKey::FromValue(key)) + (carries ? ": carries " : ": lacks ") +
                 ColumnNames(cluster_columns) + ", but with capacity " + std::to_string(dataset.capacity()) + " and " +
                 std::to_string(type_count) + " particle type(s) below it its points are " +
                 (clusters ? "clusters" : "a sample"));
    }
  }
  for (const auto& [key, mass] : children_mass) {
    const auto it = node_mass.find(key);
    if (it == node_mass.end()) continue;
    if (std::fabs(it->second - mass) > 1e-9 * std::max(std::fabs(mass), 1e-300)) {
      char buffer[160];
      std::snprintf(buffer, sizeof buffer, ": weights sum to %.17g but its children's to %.17g", it->second, mass);
      faults.Add(dataset.Where(e, NodeKey::FromValue(key)) + buffer);
    }
  }
  if (leaf_points != dataset.points(e)) {
    faults.Add("epoch " + std::to_string(e) + ": leaves hold " + std::to_string(leaf_points) + " points, the manifest says " +
               std::to_string(dataset.points(e)));
  }
  if (ids != nullptr) {
    for (const auto& [id, leaf] : id_samples) {
      try {
        const auto found = ids->Find(e, id);
        if (!found || *found != leaf) {
          faults.Add("epoch " + std::to_string(e) + ": the ID index puts particle " + std::to_string(id) + " in " +
                     (found ? found->Path() : std::string("no node")) + ", but it is in leaf " + leaf.Path());
        }
      } catch (const Error& error) {
        faults.Add(error.what());
      }
    }
  }
}

}  // namespace

VerifyReport VerifyStore(const std::string& directory, const std::function<void(const std::string&)>& on_fault) {
  VerifyReport report;
  FaultLog faults(report, on_fault);
  const Dataset dataset = Dataset::Open(directory);
  std::unique_ptr<IdIndexReader> ids;
  if (dataset.has_id_index()) {
    try {
      ids = std::make_unique<IdIndexReader>(dataset.id_index_directory());
      report.id_index_checked = true;
    } catch (const Error& error) {
      faults.Add(std::string("the ID index does not open: ") + error.what());
    }
  }
  report.epochs = dataset.epoch_count();
  for (std::uint32_t e = 0; e < dataset.epoch_count(); ++e) VerifyEpoch(dataset, e, ids.get(), faults, report.blocks_checked);
  return report;
}

}  // namespace octocosm
