#include "query/particle_lookup.h"

#include <algorithm>
#include <iterator>
#include <map>
#include <memory>
#include <unordered_map>

#include "base/error.h"
#include "query/query.h"
#include "query/read_ahead.h"
#include "query/region.h"

namespace octocosm {
namespace {

const std::string& IdIndexDirectory(const Dataset& dataset) {
  if (!dataset.has_id_index()) {
    throw Error::NotFound("store " + dataset.store().directory() +
                          " has no particle-ID index (its snapshots had no particle IDs)");
  }
  return dataset.id_index_directory();
}

}  // namespace

ParticleLocator::ParticleLocator(const Dataset& dataset)
    : dataset_(dataset),
      index_(IdIndexDirectory(dataset)),
      reads_in_flight_(dataset.epoch_count() > 0 && dataset.store().page_file(0).remote() ? kRemoteReadsInFlight : 1) {}

std::vector<ParticleLocator::LeafToRead> ParticleLocator::LeavesHolding(std::size_t nth_epoch, std::uint32_t epoch,
                                                                        std::span<const std::uint64_t> ids) const {
  if (epoch >= dataset_.epoch_count()) {
    throw Error::InvalidArgument("epoch " + std::to_string(epoch) + " is out of range: the store has " +
                                 std::to_string(dataset_.epoch_count()) + " epoch(s)");
  }
  std::map<std::uint64_t, std::vector<std::size_t>> by_leaf;  // leaf key -> positions in `ids`
  const std::vector<std::optional<NodeKey>> leaves = index_.FindAll(epoch, ids);
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (leaves[i]) by_leaf[leaves[i]->value()].push_back(i);
  }
  std::vector<LeafToRead> to_read;
  to_read.reserve(by_leaf.size());
  for (auto& [leaf_value, wanted] : by_leaf) {
    const std::optional<IndexEntry> entry = dataset_.store().Lookup({epoch, leaf_value});
    if (!entry) {
      throw Error::Corruption(dataset_.id_index_directory(), "the ID index names leaf " +
                                                                 NodeKey::FromValue(leaf_value).Path() + " of epoch " +
                                                                 std::to_string(epoch) + ", which the store lacks");
    }
    to_read.push_back({nth_epoch, epoch, *entry, std::move(wanted)});
  }
  return to_read;
}

void ParticleLocator::ForEachLeafHolding(std::span<const std::uint32_t> epochs, std::span<const std::uint64_t> ids,
                                         ColumnSet columns, std::stop_token stop, const LeafVisitor& visit) {
  // The epochs' look-ups first (the ID index's pages and the store's index),
  // then their leaves: each a list read ahead against a server.
  std::vector<std::size_t> nth_epochs(epochs.size());
  for (std::size_t n = 0; n < epochs.size(); ++n) nth_epochs[n] = n;
  ReadAhead<std::size_t, std::vector<LeafToRead>> lookups(
      std::move(nth_epochs), reads_in_flight_,
      [this, epochs, ids](std::size_t n) { return LeavesHolding(n, epochs[n], ids); });
  std::vector<LeafToRead> to_read;
  while (std::optional<std::vector<LeafToRead>> leaves = lookups.Next()) {
    std::move(leaves->begin(), leaves->end(), std::back_inserter(to_read));
  }
  struct LeafRead {
    LeafToRead leaf;
    DecodedBlock block;
    ReadCounters counters;
  };
  columns |= ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kId);
  ReadAhead<LeafToRead, LeafRead> reads(std::move(to_read), reads_in_flight_,
                                        [&dataset = dataset_, columns](const LeafToRead& leaf) {
                                          LeafRead read{leaf, {}, {}};
                                          read.block = ReadBlockColumns(dataset, leaf.epoch, leaf.entry, columns,
                                                                        read.counters);
                                          return read;
                                        });
  Matches matches;
  std::unordered_map<std::uint64_t, std::uint32_t> row_of;
  while (!stop.stop_requested()) {
    std::optional<LeafRead> read = reads.Next();
    if (!read) return;
    reads_.blocks += read->counters.blocks;
    reads_.reads += read->counters.reads;
    reads_.bytes += read->counters.bytes;
    const std::uint32_t epoch = read->leaf.epoch;
    const NodeKey leaf = read->block.header.key;
    const NodePoints& points = read->block.points;
    if (points.id.size() != read->block.header.point_count) {
      throw Error::Corruption(dataset_.Where(epoch, leaf), "the ID index points here but the block has no id column");
    }
    row_of.clear();
    row_of.reserve(points.id.size());
    for (std::size_t r = points.id.size(); r-- > 0;) row_of[points.id[r]] = static_cast<std::uint32_t>(r);  // the first row wins, as in the index
    matches.clear();
    for (std::size_t i : read->leaf.wanted) {
      const auto row = row_of.find(ids[i]);
      if (row == row_of.end()) {
        throw Error::Corruption(dataset_.Where(epoch, leaf),
                                "the ID index says particle " + std::to_string(ids[i]) + " is here, but it is not");
      }
      matches.emplace_back(i, row->second);
    }
    visit(read->leaf.nth_epoch, leaf, points, matches);
  }
}

std::vector<std::optional<ParticleState>> ParticleLocator::FindInEpoch(std::uint32_t epoch,
                                                                       std::span<const std::uint64_t> ids,
                                                                       bool with_velocity) {
  return std::move(FindInEpochs(std::span<const std::uint32_t>(&epoch, 1), ids, with_velocity).front());
}

std::vector<std::vector<std::optional<ParticleState>>> ParticleLocator::FindInEpochs(
    std::span<const std::uint32_t> epochs, std::span<const std::uint64_t> ids, bool with_velocity) {
  std::vector<std::vector<std::optional<ParticleState>>> found(epochs.size(),
                                                               std::vector<std::optional<ParticleState>>(ids.size()));
  const ColumnSet columns = with_velocity ? ColumnBit(ColumnId::kVelocity) : 0;
  ForEachLeafHolding(epochs, ids, columns, {},
                     [&](std::size_t nth_epoch, NodeKey leaf, const NodePoints& points, const Matches& matches) {
                       for (const auto& [i, row] : matches) {
                         ParticleState state;
                         state.id = ids[i];
                         state.epoch = epochs[nth_epoch];
                         state.leaf = leaf;
                         for (int a = 0; a < 3; ++a) state.position[a] = points.position[3 * row + a];
                         if (!points.velocity.empty()) {
                           state.has_velocity = true;
                           for (int a = 0; a < 3; ++a) state.velocity[a] = points.velocity[3 * row + a];
                         }
                         found[nth_epoch][i] = state;
                       }
                     });
  return found;
}

std::vector<LeafSubset> ParticleLocator::LeafSubsetsInEpoch(std::uint32_t epoch, std::span<const std::uint64_t> ids,
                                                            ColumnSet columns, std::stop_token stop) {
  std::vector<LeafSubset> subsets;
  std::vector<std::uint32_t> rows;
  ForEachLeafHolding(std::span<const std::uint32_t>(&epoch, 1), ids, columns, stop,
                     [&](std::size_t, NodeKey leaf, const NodePoints& points, const Matches& matches) {
    rows.clear();
    for (const auto& match : matches) rows.push_back(match.second);
    std::sort(rows.begin(), rows.end());
    rows.erase(std::unique(rows.begin(), rows.end()), rows.end());  // an ID asked for twice is drawn once
    subsets.push_back({leaf, SelectRows(points, rows)});
  });
  return subsets;
}

ParticleIdCollection ParticleIdsInRegion(const Dataset& dataset, std::uint32_t epoch, const Region& region,
                                         std::size_t max_ids, std::stop_token stop) {
  if (!(dataset.columns() & ColumnBit(ColumnId::kId))) {
    throw Error::InvalidArgument("the store holds no particle IDs (its input had none), so nothing can be selected by ID");
  }
  QueryOptions options;
  options.epoch = epoch;
  options.level = kMaxLevel;  // every leaf: each particle once
  options.columns = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kId);
  ParticleIdCollection found;
  struct StopReading {};  // thrown from the callback: RunQuery stops at a throw
  try {
    RunQuery(dataset, region, options, [&](const QueryBatch& batch) {
      const std::vector<std::uint64_t>& ids = batch.points.id;
      const std::size_t room = max_ids - found.ids.size();
      found.ids.insert(found.ids.end(), ids.begin(), ids.begin() + static_cast<std::ptrdiff_t>(std::min(room, ids.size())));
      if (ids.size() > room) {
        found.truncated = true;
        throw StopReading{};
      }
      if (stop.stop_requested()) {
        found.stopped = true;
        throw StopReading{};
      }
    });
  } catch (const StopReading&) {
  }
  return found;
}

std::vector<std::uint64_t> ParticleIdsInBox(const Dataset& dataset, std::uint32_t epoch, const std::array<double, 3>& lo,
                                            const std::array<double, 3>& hi) {
  const std::unique_ptr<Region> box = MakeBoxRegion(lo, hi, dataset.cube(epoch));
  return ParticleIdsInRegion(dataset, epoch, *box).ids;
}

}  // namespace octocosm
