// octocosm info and octocosm verify: what a store holds, and whether it is whole
// (the checks themselves are in index/store_verify.h).
#include <cstdio>
#include <map>
#include <string>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "base/progress.h"
#include "index/dataset.h"
#include "tools/cli_util.h"
#include "tools/commands.h"
#include "tools/store_flags.h"
#include "index/store_verify.h"

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
    std::printf("  columns %s\n", ColumnNames(dataset.columns(e)).c_str());
    if (dataset.cluster_columns() != 0) {
      std::printf("  inner nodes of clusters also %s\n", ColumnNames(dataset.cluster_columns()).c_str());
    }
    if (const auto& link = dataset.link_to_next(e)) {
      std::printf("  to the next epoch: %llu particles in both, velocity scale %.6g (fit residual %.3g, agreed by %.0f%% "
                  "of the velocity weight; least squares over all %.6g)\n",
                  static_cast<unsigned long long>(link->matched), link->velocity_scale, link->fit_residual,
                  100 * link->inlier_fraction, link->least_squares_scale);
    }
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

}  // namespace

void AddInfoCommand(CLI::App& app) {
  auto directory = std::make_shared<std::string>();
  CLI::App* cmd = app.add_subcommand("info", "Epochs, depth, nodes and points per level, bytes, bytes per point.");
  AddStoreArgument(*cmd, *directory);
  cmd->callback([directory] { PrintInfo(*directory); });
}

void AddVerifyCommand(CLI::App& app) {
  auto directory = std::make_shared<std::string>();
  CLI::App* cmd = app.add_subcommand(
      "verify",
      "Check every checksum and every structural invariant of a store (block columns, key structure, node\n"
      "capacities, weight sums of every node against its children, the manifest's checksum and its points,\n"
      "mass, nodes, leaves and depth of every epoch, ID index). Exit status 3 and a list of faults when\n"
      "anything is wrong.");
  AddStoreArgument(*cmd, *directory);
  cmd->callback([directory] {
    const VerifyReport report = VerifyStore(*directory, [](const std::string& fault) {
      std::printf("FAULT: %s\n", fault.c_str());
    });
    if (!report.faults.empty()) {
      throw Error::Corruption(*directory, std::to_string(report.faults.size()) + " fault(s) found in " +
                                              std::to_string(report.blocks_checked) + " readable blocks");
    }
    std::printf("verified %s: %llu blocks in %u epoch(s): checksums, columns, key structure, capacities, weight "
                "sums, cluster links, leaf counts%s all good\n",
                directory->c_str(), static_cast<unsigned long long>(report.blocks_checked), report.epochs,
                report.id_index_checked ? ", ID index samples" : "");
  });
}

}  // namespace octocosm
