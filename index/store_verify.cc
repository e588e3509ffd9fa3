// octocosm verify: every checksum and structural invariant of a dataset store.
#include "index/store_verify.h"

#include <algorithm>
#include <bitset>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "base/error.h"
#include "index/block_codec.h"
#include "index/dataset.h"
#include "index/id_index.h"
#include "storage/checksum.h"

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

// What the blocks of one epoch add up to, gathered in one pass over them.
struct EpochTally {
  std::vector<IndexEntry> entries;
  std::unordered_set<std::uint64_t> present, has_children;
  std::unordered_map<std::uint64_t, double> node_mass;      // sum of a node's own weights
  std::unordered_map<std::uint64_t, double> children_mass;  // sum of its children's node masses
  // Of every node with children: the particle types of their points, and
  // whether the node carries the cluster columns.
  std::unordered_map<std::uint64_t, std::bitset<256>> children_types;
  std::unordered_map<std::uint64_t, bool> carries_cluster_columns;
  std::uint64_t leaf_points = 0;
  std::uint64_t leaves = 0;
  double leaf_mass = 0;
  int depth = 0;
  std::vector<std::pair<std::uint64_t, NodeKey>> id_samples;  // (ID, its leaf)
};

std::string Text(double x) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.17g", x);
  return buffer;
}

void ScanKeys(const Dataset& dataset, std::uint32_t e, FaultLog& faults, EpochTally& tally) {
  dataset.store().Scan(e, 0, ~std::uint64_t{0}, [&](const IndexEntry& entry) {
    tally.entries.push_back(entry);
    return true;
  });
  for (const IndexEntry& entry : tally.entries) {
    const NodeKey key = NodeKey::FromValue(entry.key);
    if (!key.IsValid()) {
      faults.Add("epoch " + std::to_string(e) + ": invalid node key " + Hex64(entry.key));
      continue;
    }
    tally.present.insert(entry.key);
    if (key.level() > 0) tally.has_children.insert(key.Parent().value());
  }
}

// Checks the links between inner nodes of clusters and their children's
// points (index/block_codec.h, child_cluster and refine_bound): each cluster's
// mass is its members', each child point lies in its cluster's octant, and
// each cluster's bounds hold its members' (the sphere about it holds theirs,
// its error and mass bounds are at least theirs). Blocks come in depth-first
// order, so the nodes whose children are still to come form a path from the
// root: only their links are held.
class ClusterLinkChecker {
 public:
  ClusterLinkChecker(const Dataset& dataset, std::uint32_t e, const EpochTally& tally, FaultLog& faults)
      : dataset_(dataset), e_(e), faults_(faults) {
    for (const IndexEntry& entry : tally.entries) point_count_[entry.key] = entry.point_count;
  }

  // A block's points, in depth-first order.
  void Visit(NodeKey key, const NodePoints& points) {
    while (!path_.empty() && !path_.back().key.IsAncestorOrSelf(key)) Finish();
    if (!path_.empty() && path_.back().key == key.Parent()) CheckMembers(path_.back(), key, points);
    if (!points.child_cluster.empty()) Start(key, points);
  }

  void FinishAll() {
    while (!path_.empty()) Finish();
  }

 private:
  struct Parent {
    NodeKey key;
    NodePoints points;
    std::array<std::uint64_t, 9> child_first{};  // the first entry of each child octant's points
    std::vector<double> member_mass;
    std::uint64_t faults = 0;
  };

  void Start(NodeKey key, const NodePoints& points) {
    Parent parent{key, points, {}, std::vector<double>(points.size(), 0.0)};
    for (int o = 0; o < 8; ++o) {
      const auto child = point_count_.find(key.Child(o).value());
      parent.child_first[o + 1] = parent.child_first[o] + (child == point_count_.end() ? 0 : child->second);
    }
    if (parent.child_first[8] != points.child_cluster.size()) {
      Fault(parent, "links " + std::to_string(points.child_cluster.size()) + " points of its children to clusters, "
                    "its children hold " + std::to_string(parent.child_first[8]));
    }
    path_.push_back(std::move(parent));
  }

  void CheckMembers(Parent& parent, NodeKey child, const NodePoints& points) {
    const int o = child.OctantInParent();
    const std::uint64_t first = parent.child_first[o];
    const NodePoints& clusters = parent.points;
    if (first + points.size() > clusters.child_cluster.size()) return;  // the count is faulted already
    for (std::size_t k = 0; k < points.size(); ++k) {
      const std::uint32_t c = clusters.child_cluster[first + k];
      if (c < clusters.octant_offsets[o] || c >= clusters.octant_offsets[o + 1]) {
        Fault(parent, "point " + std::to_string(k) + " of child " + child.Path() + " belongs to cluster " +
                      std::to_string(c) + ", which lies in another octant");
        continue;
      }
      parent.member_mass[c] += points.weight[k];
      const float* bound = &clusters.refine_bound[3 * c];
      double d2 = 0;
      for (int a = 0; a < 3; ++a) d2 += std::pow(points.position[3 * k + a] - clusters.position[3 * c + a], 2);
      const bool inner = !points.refine_bound.empty();
      const double reach = std::sqrt(d2) + (inner ? double{points.refine_bound[3 * k]} : 0.0);
      const bool holds = reach <= bound[0] && (!inner || (points.refine_bound[3 * k + 1] <= bound[1] &&
                                                          points.refine_bound[3 * k + 2] <= bound[2]));
      if (!holds) {
        Fault(parent, "the refine bound of cluster " + std::to_string(c) + " (" + Text(bound[0]) + ", " +
                      Text(bound[1]) + ", " + Text(bound[2]) + ") does not hold point " + std::to_string(k) +
                      " of child " + child.Path() + " (reach " + Text(reach) +
                      (inner ? ", " + Text(points.refine_bound[3 * k + 1]) + ", " + Text(points.refine_bound[3 * k + 2])
                             : std::string()) +
                      ")");
      }
    }
  }

  void Finish() {
    Parent& parent = path_.back();
    double node_mass = 0;
    for (const double w : parent.points.weight) node_mass += w;
    for (std::size_t c = 0; c < parent.points.size() && parent.faults == 0; ++c) {
      // Each decoded weight is within a unit (2.3e-10 of its node's mass) of its value.
      if (std::fabs(parent.member_mass[c] - parent.points.weight[c]) > 1e-8 * node_mass) {
        Fault(parent, "cluster " + std::to_string(c) + " weighs " + Text(parent.points.weight[c]) +
                      " but its members " + Text(parent.member_mass[c]));
      }
    }
    path_.pop_back();
  }

  // One fault a node: a damaged link column would repeat for every point.
  void Fault(Parent& parent, const std::string& what) {
    if (parent.faults++ == 0) faults_.Add(dataset_.Where(e_, parent.key) + ": " + what);
  }

  const Dataset& dataset_;
  std::uint32_t e_;
  FaultLog& faults_;
  std::unordered_map<std::uint64_t, std::uint64_t> point_count_;
  std::vector<Parent> path_;
};

// Reads, checksums and decodes one block and adds it to the tally.
void VerifyBlock(const Dataset& dataset, std::uint32_t e, const IndexEntry& entry, std::mt19937_64& rng,
                 FaultLog& faults, EpochTally& tally, ClusterLinkChecker& links) {
  const NodeKey key = NodeKey::FromValue(entry.key);
  const std::string where = dataset.Where(e, key);
  const Bytes bytes = dataset.store().ReadBlock({e, entry.key});
  const DecodedBlock block = DecodeBlock(bytes, kAllColumns | kClusterLinkColumns, key, dataset.cube(e), where);
  const std::size_t n = block.header.point_count;
  if (n != entry.point_count) {
    faults.Add(where + ": index says " + std::to_string(entry.point_count) + " points, block holds " + std::to_string(n));
  }
  const ColumnSet declared = dataset.columns(e);
  // Inner nodes of clusters carry these besides; whether a node's points are
  // clusters follows from its children's particle types (CheckClusterColumns).
  const ColumnSet cluster_columns = dataset.cluster_columns();
  ColumnSet carried = 0;
  for (const BlockColumn& column : block.header.columns) carried |= ColumnBit(column.id);
  const bool leaf = !tally.has_children.count(entry.key);
  const bool with_cluster_columns = !leaf && cluster_columns != 0 && carried == (declared | cluster_columns);
  if (carried != declared && !with_cluster_columns) {
    faults.Add(where + ": carries the columns " + ColumnNames(carried) + ", the manifest declares " +
               ColumnNames(declared) +
               (cluster_columns != 0 ? (leaf ? " for a leaf" : " (and " + ColumnNames(cluster_columns) + " for clusters)")
                                     : ""));
  }
  if (!leaf) tally.carries_cluster_columns[entry.key] = with_cluster_columns;
  if (key.level() > 0 && cluster_columns != 0) {
    std::bitset<256>& types = tally.children_types[key.Parent().value()];
    for (const std::uint8_t t : block.points.type) types.set(t);
  }
  if (n > dataset.capacity() && !(leaf && key.level() == dataset.max_level())) {
    faults.Add(where + ": " + std::to_string(n) + " points exceed the node capacity " + std::to_string(dataset.capacity()));
  }
  if (key.level() > 0 && !tally.present.count(key.Parent().value())) {
    faults.Add(where + ": its parent " + key.Parent().Path() + " is missing");
  }
  links.Visit(key, block.points);
  double mass = 0;
  for (double w : block.points.weight) mass += w;
  tally.node_mass[entry.key] = mass;
  if (key.level() > 0) tally.children_mass[key.Parent().value()] += mass;
  if (!leaf) return;
  tally.leaf_points += n;
  tally.leaf_mass += mass;
  ++tally.leaves;
  tally.depth = std::max(tally.depth, key.level());
  for (std::size_t p = 0; p < block.points.id.size(); ++p) {
    if (tally.id_samples.size() < 1000) tally.id_samples.emplace_back(block.points.id[p], key);
    else if (rng() % 64 == 0) tally.id_samples[rng() % tally.id_samples.size()] = {block.points.id[p], key};
  }
}

// A node's points are clusters exactly when the builder could give every
// child octant and particle type of its population a cluster of its own
// (index/subtree_builder.cc, AggregateParent); otherwise they are a sample.
void CheckClusterColumns(const Dataset& dataset, std::uint32_t e, const EpochTally& tally, FaultLog& faults) {
  const ColumnSet cluster_columns = dataset.cluster_columns();
  for (const auto& [key, carries] : tally.carries_cluster_columns) {
    const auto types = tally.children_types.find(key);
    if (types == tally.children_types.end()) continue;  // no child was read: faulted already
    const std::size_t type_count = std::max<std::size_t>(1, types->second.count());
    const bool clusters = dataset.capacity() >= 8 * type_count;
    if (carries != clusters) {
      faults.Add(dataset.Where(e, NodeKey::FromValue(key)) + (carries ? ": carries " : ": lacks ") +
                 ColumnNames(cluster_columns) + ", but with capacity " + std::to_string(dataset.capacity()) + " and " +
                 std::to_string(type_count) + " particle type(s) below it its points are " +
                 (clusters ? "clusters" : "a sample"));
    }
  }
}

void CheckMassConservation(const Dataset& dataset, std::uint32_t e, const EpochTally& tally, FaultLog& faults) {
  for (const auto& [key, mass] : tally.children_mass) {
    const auto it = tally.node_mass.find(key);
    if (it == tally.node_mass.end()) continue;
    if (std::fabs(it->second - mass) > 1e-9 * std::max(std::fabs(mass), 1e-300)) {
      faults.Add(dataset.Where(e, NodeKey::FromValue(key)) + ": weights sum to " + Text(it->second) +
                 " but its children's to " + Text(mass));
    }
  }
}

// The dataset metadata's record of the epoch against what its blocks hold.
void CheckEpochSummary(const Dataset& dataset, std::uint32_t e, const EpochTally& tally, FaultLog& faults) {
  const EpochSummary& summary = dataset.summary(e);
  const std::string epoch = "epoch " + std::to_string(e) + ": ";
  const auto mismatch = [&](const std::string& what, const std::string& blocks, const std::string& manifest) {
    faults.Add(epoch + what + " " + blocks + ", the manifest says " + manifest);
  };
  if (tally.leaf_points != summary.points) {
    mismatch("leaves hold", std::to_string(tally.leaf_points) + " points", std::to_string(summary.points));
  }
  if (summary.nodes && *summary.nodes != tally.entries.size()) {
    mismatch("the index holds", std::to_string(tally.entries.size()) + " nodes", std::to_string(*summary.nodes));
  }
  if (summary.leaves && *summary.leaves != tally.leaves) {
    mismatch("the tree has", std::to_string(tally.leaves) + " leaves", std::to_string(*summary.leaves));
  }
  if (summary.depth && *summary.depth != tally.depth) {
    mismatch("the deepest leaf is at level", std::to_string(tally.depth), std::to_string(*summary.depth));
  }
  const auto root = tally.node_mass.find(NodeKey::Root().value());
  if (summary.mass && root != tally.node_mass.end()) {
    const double mass = *summary.mass;
    for (const auto& [what, blocks] : {std::pair<const char*, double>{"the leaves' weights sum to", tally.leaf_mass},
                                       {"the root's weights sum to", root->second}}) {
      if (!(std::fabs(blocks - mass) <= 1e-9 * std::max(std::fabs(mass), 1e-300))) {
        mismatch(std::string(what), Text(blocks), "a mass of " + Text(mass));
      }
    }
  }
}

void CheckIdSamples(std::uint32_t e, const EpochTally& tally, const IdIndexReader& ids, FaultLog& faults) {
  for (const auto& [id, leaf] : tally.id_samples) {
    try {
      const auto found = ids.Find(e, id);
      if (!found || *found != leaf) {
        faults.Add("epoch " + std::to_string(e) + ": the ID index puts particle " + std::to_string(id) + " in " +
                   (found ? found->Path() : std::string("no node")) + ", but it is in leaf " + leaf.Path());
      }
    } catch (const Error& error) {
      faults.Add(error.what());
    }
  }
}

void VerifyEpoch(const Dataset& dataset, std::uint32_t e, const IdIndexReader* ids, FaultLog& faults,
                 std::uint64_t& blocks_checked) {
  EpochTally tally;
  ScanKeys(dataset, e, faults, tally);
  std::mt19937_64 rng(e);
  // Depth-first, so that the cluster links are checked holding one path of
  // nodes (invalid keys, faulted already, last).
  std::vector<IndexEntry> order = tally.entries;
  std::stable_sort(order.begin(), order.end(), [](const IndexEntry& a, const IndexEntry& b) {
    const NodeKey ka = NodeKey::FromValue(a.key), kb = NodeKey::FromValue(b.key);
    if (ka.IsValid() != kb.IsValid()) return ka.IsValid();
    return ka.IsValid() && PreorderLess{}(ka, kb);
  });
  ClusterLinkChecker links(dataset, e, tally, faults);
  for (const IndexEntry& entry : order) {
    if (!NodeKey::FromValue(entry.key).IsValid()) continue;
    try {
      VerifyBlock(dataset, e, entry, rng, faults, tally, links);
      ++blocks_checked;
    } catch (const Error& error) {
      faults.Add(error.what());
    }
  }
  links.FinishAll();
  CheckClusterColumns(dataset, e, tally, faults);
  CheckMassConservation(dataset, e, tally, faults);
  CheckEpochSummary(dataset, e, tally, faults);
  if (ids != nullptr) CheckIdSamples(e, tally, *ids, faults);
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
