// A dataset store opened for use: the page-file store plus what the octree
// needs to interpret it (each epoch's cube, the node capacity, the depth
// limit), read from the manifest's dataset metadata written by ingest.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "index/block_codec.h"
#include "index/cube.h"
#include "index/morton.h"
#include "index/sampler.h"
#include "storage/store_reader.h"

namespace octocosm {

// What ingest recorded about the step from one epoch to the next
// (docs/FORMAT.md 5.2, "to_next"): the least-squares scale s that turns the
// mean of a particle's velocities at both ends into its displacement
// (d ~ s (v_e + v_e+1) / 2), the fit's relative residual, and the largest
// displacement of any particle.
struct EpochLink {
  double velocity_scale = 0;
  double fit_residual = 1;
  double max_displacement = 0;
};

class Dataset {
 public:
  // Opens the store at `directory`; throws Error (kCorruption when the
  // dataset metadata is missing or malformed, as StoreReader::Open otherwise).
  static Dataset Open(const std::string& directory);

  const StoreReader& store() const { return store_; }
  std::uint32_t epoch_count() const { return store_.epoch_count(); }
  const Cube& cube(std::uint32_t epoch) const { return cubes_.at(epoch); }
  std::uint64_t points(std::uint32_t epoch) const { return points_.at(epoch); }
  // The total mass of the epoch (the root's weights).
  double mass(std::uint32_t epoch) const { return masses_.at(epoch); }
  // Optional columns the blocks carry.
  bool has_velocity() const { return has_velocity_; }
  bool has_displacement() const { return has_displacement_; }
  // The columns the blocks may carry (from the attribute schema).
  ColumnSet columns() const { return columns_; }
  // The link from `epoch` to the next, when ingest recorded one.
  const std::optional<EpochLink>& link_to_next(std::uint32_t epoch) const { return links_.at(epoch); }
  std::size_t capacity() const { return capacity_; }
  // The subselection's settings the store was built with.
  const SamplerOptions& sampler() const { return sampler_; }
  int max_level() const { return max_level_; }
  bool has_id_index() const { return !id_index_.empty(); }
  // The directory of the ID index store (empty when the dataset has no IDs).
  const std::string& id_index_directory() const { return id_index_; }
  // "file epoch N block rXXXX": how errors name a block.
  std::string Where(std::uint32_t epoch, NodeKey key) const;

 private:
  explicit Dataset(StoreReader store) : store_(std::move(store)) {}

  StoreReader store_;
  std::vector<Cube> cubes_;
  std::vector<std::uint64_t> points_;
  std::vector<double> masses_;
  bool has_velocity_ = false;
  bool has_displacement_ = false;
  ColumnSet columns_ = 0;
  std::vector<std::optional<EpochLink>> links_;
  std::size_t capacity_ = 0;
  SamplerOptions sampler_;
  int max_level_ = kMaxLevel;
  std::string id_index_;
};

}  // namespace octocosm
