// Particle-ID look-ups: where particles are in one epoch, or their rows as
// stored. The ID index (index/id_index.h) names the leaf that holds
// the ID; only that leaf's id and position columns (and velocity, when asked)
// are read, and each leaf once however many of the IDs asked for it holds.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <stop_token>
#include <vector>

#include "index/dataset.h"
#include "index/id_index.h"
#include "index/node_points.h"
#include "query/column_reader.h"
#include "query/region.h"

namespace octocosm {

// Some rows of one leaf, all the columns asked for.
struct LeafSubset {
  NodeKey leaf;
  NodePoints points;  // grouped by child octant like the leaf's (SelectRows)
};

struct ParticleState {
  std::uint64_t id = 0;
  std::uint32_t epoch = 0;
  NodeKey leaf;
  std::array<double, 3> position{};  // dequantized: within leaf size / 131072 per axis
  bool has_velocity = false;
  std::array<float, 3> velocity{};
};

class ParticleLocator {
 public:
  // Throws Error::NotFound when the dataset has no ID index (its input had no
  // particle IDs), as IdIndexReader otherwise.
  explicit ParticleLocator(const Dataset& dataset);

  // One entry per ID, in the order given: the particle's state in `epoch`, or
  // nullopt when the epoch has no such ID. Throws Error::InvalidArgument for
  // an epoch out of range, Error::Corruption when the index names a leaf
  // that does not hold the ID.
  std::vector<std::optional<ParticleState>> FindInEpoch(std::uint32_t epoch, std::span<const std::uint64_t> ids,
                                                        bool with_velocity);
  // FindInEpoch for each of `epochs`, in that order. Against a store on a
  // server the epochs' look-ups, and then their leaves, are read several at
  // once: a trajectory through many epochs waits a few round trips, not a few
  // per epoch.
  std::vector<std::vector<std::optional<ParticleState>>> FindInEpochs(std::span<const std::uint32_t> epochs,
                                                                      std::span<const std::uint64_t> ids,
                                                                      bool with_velocity);
  // The particles of `ids` that `epoch` holds, as stored at full detail:
  // for each leaf that holds some, those rows with the columns in `columns`
  // (position and id always) that the store has; in leaf key order. What a
  // renderer draws over any level of detail to show a selection exactly.
  // Returns what was read so far when `stop` is requested. Throws like
  // FindInEpoch.
  std::vector<LeafSubset> LeafSubsetsInEpoch(std::uint32_t epoch, std::span<const std::uint64_t> ids,
                                             ColumnSet columns, std::stop_token stop = {});

  const ReadCounters& reads() const { return reads_; }

 private:
  using Matches = std::vector<std::pair<std::size_t, std::uint32_t>>;  // (position in the IDs asked for, row)
  using LeafVisitor =
      std::function<void(std::size_t nth_epoch, NodeKey leaf, const NodePoints& points, const Matches& matches)>;
  // A leaf that holds some of the IDs asked for.
  struct LeafToRead {
    std::size_t nth_epoch = 0;  // position in the epochs asked for
    std::uint32_t epoch = 0;
    IndexEntry entry;
    std::vector<std::size_t> wanted;  // positions in the IDs asked for
  };
  // The leaves of `epoch` that hold some of `ids`, in key order.
  std::vector<LeafToRead> LeavesHolding(std::size_t nth_epoch, std::uint32_t epoch,
                                        std::span<const std::uint64_t> ids) const;
  // Reads each leaf of `epochs` holding some of `ids` once (`columns`, with
  // position and id) and hands it to `visit` with the rows of those IDs,
  // epoch by epoch in the order given, each epoch's leaves in key order.
  void ForEachLeafHolding(std::span<const std::uint32_t> epochs, std::span<const std::uint64_t> ids,
                          ColumnSet columns, std::stop_token stop, const LeafVisitor& visit);

  const Dataset& dataset_;
  IdIndexReader index_;
  std::size_t reads_in_flight_ = 1;  // several against a server
  ReadCounters reads_;
};

// The IDs of the particles of `epoch` in `region`, read from the leaves
// that meet it (only their id and position columns): a selection by region.
// Reading stops early once more than `max_ids` particles are found (the
// first max_ids are kept and `truncated` is set), and, leaving the IDs found
// so far, when `stop` is requested (a viewer's selection thread that is no
// longer wanted). Throws Error::InvalidArgument when the store has no
// particle IDs, as RunQuery otherwise.
struct ParticleIdCollection {
  std::vector<std::uint64_t> ids;
  bool truncated = false;  // the region holds more than max_ids particles
  bool stopped = false;    // `stop` was requested before the whole region was read
};
ParticleIdCollection ParticleIdsInRegion(const Dataset& dataset, std::uint32_t epoch, const Region& region,
                                         std::size_t max_ids = SIZE_MAX, std::stop_token stop = {});

// The IDs of every particle of `epoch` inside the closed box [lo, hi]
// (periodic boxes as in query/region.h): ParticleIdsInRegion of the box.
std::vector<std::uint64_t> ParticleIdsInBox(const Dataset& dataset, std::uint32_t epoch, const std::array<double, 3>& lo,
                                            const std::array<double, 3>& hi);

}  // namespace octocosm
