// Particle-ID look-ups: where a particle is in one epoch, or in every epoch
// (its trajectory). The ID index (index/id_index.h) names the leaf that holds
// the ID; only that leaf's id and position columns (and velocity, when asked)
// are read, and each leaf once however many of the IDs asked for it holds.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <stop_token>
#include <vector>

#include "index/column_reader.h"
#include "index/dataset.h"
#include "index/id_index.h"
#include "index/region.h"

namespace octocosm {

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
  // The particle in every epoch (nullopt where it is missing).
  std::vector<std::optional<ParticleState>> Trajectory(std::uint64_t id, bool with_velocity);

  const ReadCounters& reads() const { return reads_; }

 private:
  const Dataset& dataset_;
  IdIndexReader index_;
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
// (periodic boxes as in index/region.h): ParticleIdsInRegion of the box.
std::vector<std::uint64_t> ParticleIdsInBox(const Dataset& dataset, std::uint32_t epoch, const std::array<double, 3>& lo,
                                            const std::array<double, 3>& hi);

}  // namespace octocosm
