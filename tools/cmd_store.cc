// octocosm info and octocosm verify: what a store holds, and whether it is whole.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <CLI/CLI.hpp>

#include "index/block_codec.h"
#include "index/dataset.h"
#include "index/id_index.h"
#include "storage/error.h"
#include "tools/cli_util.h"
#include "tools/commands.h"
#include "tools/progress.h"

namespace octocosm {
namespace {

struct LevelStats {
  std::uint64_t nodes = 0, points = 0, bytes = 0;
};

void PrintInfo(const std::string& directory) {
  const Dataset dataset = Dataset::Open(directory);
  const StoreReader& store = dataset.store();
  std::printf("store %s\n  page size %s, %u epoch(s), node capacity %zu, depth limit %d, ID index: %s\n",
              directory.c_str(), HumanBytes(store.page_size()).c_str(), store.epoch_count(), dataset.capacity(),
              dataset.max_level(), dataset.has_id_index() ? "yes" : "no");
  std::uint64_t total_bytes = 0, total_points = 0;
  for (std::uint32_t e = 0; e < store.epoch_count(); ++e) {
    const EpochInfo& info = store.epochs()[e];
    const Cube& cube = dataset.cube(e);
    std::map<int, LevelStats> levels;
    store.Scan(e, 0, ~std::uint64_t{0}, [&](const IndexEntry& entry) {
      LevelStats& s = levels[NodeKey::FromValue(entry.key).level()];
      ++s.nodes;
      s.points += entry.point_count;
      s.bytes += entry.byte_length;
      return true;
    });
    const std::uint64_t points = dataset.points(e);
    std::printf("epoch %u: %s, time %.6g, redshift %.6g, %s points, %llu blocks, %s, %.1f bytes/point\n", e,
                info.file.c_str(), info.time, info.redshift, HumanCount(static_cast<double>(points)).c_str(),
                static_cast<unsigned long long>(info.block_count), HumanBytes(static_cast<double>(info.file_size)).c_str(),
                points ? static_cast<double>(info.file_size) / static_cast<double>(points) : 0.0);
    std::printf("  cube origin (%.9g, %.9g, %.9g) size %.9g%s, depth %d\n", cube.origin[0], cube.origin[1], cube.origin[2],
                cube.size, cube.periodic ? " (periodic box)" : "", levels.empty() ? 0 : levels.rbegin()->first);
    std::printf("  %5s %10s %14s %12s\n", "level", "nodes", "points", "bytes");
    for (const auto& [level, s] : levels) {
      std::printf("  %5d %10llu %14llu %12s\n", level, static_cast<unsigned long long>(s.nodes),
                  static_cast<unsigned long long>(s.points), HumanBytes(static_cast<double>(s.bytes)).c_str());
    }
    total_bytes += info.file_size;
    total_points += points;
  }
  std::printf("total: %s in page files, %.1f bytes per input point\n", HumanBytes(static_cast<double>(total_bytes)).c_str(),
              total_points ? static_cast<double>(total_bytes) / static_cast<double>(total_points) : 0.0);
}

// Collects faults instead of stopping at the first, so one run reports all damage.
class FaultLog {
 public:
  void Add(const std::string& message) {
    if (count_ < 50) std::printf("FAULT: %s\n", message.c_str());
    ++count_;
  }
  std::uint64_t count() const { return count_; }

 private:
  std::uint64_t count_ = 0;
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
      const bool leaf = !has_children.count(entry.key);
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

void Verify(const std::string& directory) {
  const Dataset dataset = Dataset::Open(directory);
  std::unique_ptr<IdIndexReader> ids;
  if (dataset.has_id_index()) ids = std::make_unique<IdIndexReader>(dataset.id_index_directory());
  FaultLog faults;
  std::uint64_t blocks = 0;
  for (std::uint32_t e = 0; e < dataset.epoch_count(); ++e) VerifyEpoch(dataset, e, ids.get(), faults, blocks);
  if (faults.count() > 0) {
    throw Error::Corruption(directory, std::to_string(faults.count()) + " fault(s) found in " + std::to_string(blocks) +
                                           " readable blocks (the first 50 are listed above)");
  }
  std::printf("verified %s: %llu blocks in %u epoch(s): checksums, columns, key structure, capacities, weight sums, "
              "leaf counts%s all good\n",
              directory.c_str(), static_cast<unsigned long long>(blocks), dataset.epoch_count(),
              ids ? ", ID index samples" : "");
}

}  // namespace

void AddInfoCommand(CLI::App& app) {
  auto directory = std::make_shared<std::string>();
  CLI::App* cmd = app.add_subcommand("info", "Epochs, depth, nodes and points per level, bytes, bytes per point.");
  cmd->add_option("store", *directory, "store directory")->required();
  cmd->callback([directory] { PrintInfo(*directory); });
}

void AddVerifyCommand(CLI::App& app) {
  auto directory = std::make_shared<std::string>();
  CLI::App* cmd = app.add_subcommand(
      "verify",
      "Check every checksum and every structural invariant of a store (block columns, key structure, node\n"
      "capacities, weight sums of every node against its children, leaf counts, ID index). Exit status 3 and\n"
      "a list of faults when anything is wrong.");
  cmd->add_option("store", *directory, "store directory")->required();
  cmd->callback([directory] { Verify(*directory); });
}

}  // namespace octocosm
