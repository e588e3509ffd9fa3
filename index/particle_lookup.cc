#include "index/particle_lookup.h"

#include <algorithm>
#include <map>
#include <memory>
#include <unordered_map>

#include "index/query.h"
#include "index/region.h"
#include "storage/error.h"

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

ParticleLocator::ParticleLocator(const Dataset& dataset) : dataset_(dataset), index_(IdIndexDirectory(dataset)) {}

std::vector<std::optional<ParticleState>> ParticleLocator::FindInEpoch(std::uint32_t epoch,
                                                                       std::span<const std::uint64_t> ids,
                                                                       bool with_velocity) {
  if (epoch >= dataset_.epoch_count()) {
    throw Error::InvalidArgument("epoch " + std::to_string(epoch) + " is out of range: the store has " +
                                 std::to_string(dataset_.epoch_count()) + " epoch(s)");
  }
  std::vector<std::optional<ParticleState>> found(ids.size());
  std::map<std::uint64_t, std::vector<std::size_t>> by_leaf;  // leaf key -> positions in `ids`
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (const auto leaf = index_.Find(epoch, ids[i])) by_leaf[leaf->value()].push_back(i);
  }
  ColumnSet columns = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kId);
  if (with_velocity) columns |= ColumnBit(ColumnId::kVelocity);
  for (const auto& [leaf_value, wanted] : by_leaf) {
    const NodeKey leaf = NodeKey::FromValue(leaf_value);
    const std::optional<IndexEntry> entry = dataset_.store().Lookup({epoch, leaf_value});
    if (!entry) {
      throw Error::Corruption(dataset_.id_index_directory(), "the ID index names leaf " + leaf.Path() + " of epoch " +
                                                                 std::to_string(epoch) + ", which the store lacks");
    }
    const DecodedBlock block = ReadBlockColumns(dataset_, epoch, *entry, columns, reads_);
    const NodePoints& points = block.points;
    if (points.id.size() != block.header.point_count) {
      throw Error::Corruption(dataset_.Where(epoch, leaf), "the ID index points here but the block has no id column");
    }
    std::unordered_map<std::uint64_t, std::size_t> row_of;
    row_of.reserve(points.id.size());
    for (std::size_t r = points.id.size(); r-- > 0;) row_of[points.id[r]] = r;  // the first row wins, as in the index
    for (std::size_t i : wanted) {
      const auto row = row_of.find(ids[i]);
      if (row == row_of.end()) {
        throw Error::Corruption(dataset_.Where(epoch, leaf),
                                "the ID index says particle " + std::to_string(ids[i]) + " is here, but it is not");
      }
      ParticleState state;
      state.id = ids[i];
      state.epoch = epoch;
      state.leaf = leaf;
      for (int a = 0; a < 3; ++a) state.position[a] = points.position[3 * row->second + a];
      if (!points.velocity.empty()) {
        state.has_velocity = true;
        for (int a = 0; a < 3; ++a) state.velocity[a] = points.velocity[3 * row->second + a];
      }
      found[i] = state;
    }
  }
  return found;
}

std::vector<std::optional<ParticleState>> ParticleLocator::Trajectory(std::uint64_t id, bool with_velocity) {
  std::vector<std::optional<ParticleState>> path;
  for (std::uint32_t e = 0; e < dataset_.epoch_count(); ++e) {
    path.push_back(FindInEpoch(e, std::span<const std::uint64_t>(&id, 1), with_velocity)[0]);
  }
  return path;
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
