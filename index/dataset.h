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

// How an epoch links to the next, as ingest fitted it (docs/FORMAT.md 5.2,
// `to_next`; tools/ingest/epoch_join.h, VelocityScaleFit). A renderer moves a
// particle between epochs e and e + 1 along the cubic Hermite curve from p_e
// to p_e+1 with tangents velocity_scale * v_e and velocity_scale * v_e+1.
struct EpochLink {
  double velocity_scale = 0;       // s; 0 when it could not be fitted (no velocities)
  double fit_residual = 1;         // relative residual of d ~ s (v_e + v_e+1) / 2 over all; 1 = no fit
  double least_squares_scale = 0;  // the plain least-squares s over all particles
  double inlier_fraction = 0;      // share of the velocity weight that agrees with s
  std::uint64_t matched = 0;       // particles found in both epochs
  // How far any matched particle's path between the two epochs (linear or
  // Hermite) strays from its position at either end; 0 when not recorded.
  double max_excursion = 0;
};

// A moment of a cosmological series: a redshift z or a scale factor
// a = 1 / (1 + z).
struct PhysicalTime {
  enum class Scale { kRedshift, kScaleFactor };
  Scale scale = Scale::kScaleFactor;
  double value = 1;

  // a. Throws Error::InvalidArgument for a redshift that is not > -1 or a
  // scale factor that is not > 0 (or either not finite).
  double ScaleFactor() const;
  // "redshift 2", "scale factor 0.25": how messages name it.
  std::string ToString() const;
};

// The fractional epoch e + t that shows `time` in a series whose epochs have
// the scale factors `epoch_scale_factors` (empty for an epoch whose snapshot
// records none): epochs e and e + 1 are the recorded times on either side of
// it, and t runs linearly in the scale factor from one to the other, however
// unevenly the epochs are spaced. A scale factor within a relative 1e-7 of an
// epoch's is that epoch: headers record time and redshift apart, some in
// single precision, and a redshift given as recorded must show its epoch
// exactly. Throws Error::InvalidArgument naming `store` when an epoch records
// no scale factor, when the scale factors do not increase strictly from epoch
// to epoch, or when the time lies outside theirs.
double FractionalEpochAt(const std::vector<std::optional<double>>& epoch_scale_factors, const PhysicalTime& time,
                         const std::string& store);

// What the dataset metadata records about one epoch's tree, as ingest
// counted it while building; `verify` checks it against the blocks. Stores
// built by hand (tests) may leave out what they do not know.
struct EpochSummary {
  std::uint64_t points = 0;  // particles in the leaves
  std::optional<double> mass;  // of all particles
  std::optional<std::uint64_t> nodes;
  std::optional<std::uint64_t> leaves;
  std::optional<int> depth;  // the deepest leaf's level
};

class Dataset {
 public:
  // Opens the store at `directory`; throws Error (kCorruption when the
  // dataset metadata is missing or malformed, as StoreReader::Open otherwise).
  static Dataset Open(const std::string& directory);

  const StoreReader& store() const { return store_; }
  std::uint32_t epoch_count() const { return store_.epoch_count(); }
  const Cube& cube(std::uint32_t epoch) const { return cubes_.at(epoch); }
  std::uint64_t points(std::uint32_t epoch) const { return summaries_.at(epoch).points; }
  const EpochSummary& summary(std::uint32_t epoch) const { return summaries_.at(epoch); }
  // The columns some block of some epoch carries.
  ColumnSet columns() const {
    return every_epoch_columns_ | forward_columns_ | backward_columns_ | cluster_columns_;
  }
  std::size_t capacity() const { return capacity_; }
  // The subselection's settings the store was built with.
  const SamplerOptions& sampler() const { return sampler_; }
  int max_level() const { return max_level_; }
  // The columns every block of `epoch` carries, as the manifest declares them.
  ColumnSet columns(std::uint32_t epoch) const;
  // The columns that the block of every inner node whose points are clusters
  // (index/aggregator.h) carries besides columns(epoch), in every epoch: the
  // blobs' shapes (the manifest's has_shape) and, in a dataset with
  // velocities, the velocity dispersion (has_velocity_dispersion). Leaves,
  // and inner nodes whose points are a sample, lack them.
  ColumnSet cluster_columns() const { return cluster_columns_; }
  // How `epoch` links to the next; empty for the last epoch and for a series
  // without IDs.
  const std::optional<EpochLink>& link_to_next(std::uint32_t epoch) const { return links_.at(epoch); }
  // The scale factor of the epoch's snapshot: its recorded time, where the
  // snapshot's header says the run is cosmological; empty otherwise.
  const std::optional<double>& scale_factor(std::uint32_t epoch) const { return scale_factors_.at(epoch); }
  // FractionalEpochAt over this store's epochs.
  double FractionalEpochAt(const PhysicalTime& time) const;
  bool has_id_index() const { return !id_index_.empty(); }
  // The directory of the ID index store (empty when the dataset has no IDs).
  const std::string& id_index_directory() const { return id_index_; }
  // "file epoch N block rXXXX": how errors name a block.
  std::string Where(std::uint32_t epoch, NodeKey key) const;

 private:
  explicit Dataset(StoreReader store) : store_(std::move(store)) {}

  StoreReader store_;
  std::vector<Cube> cubes_;
  std::vector<EpochSummary> summaries_;
  std::vector<std::optional<EpochLink>> links_;
  std::vector<std::optional<double>> scale_factors_;
  ColumnSet every_epoch_columns_ = 0;  // the columns of every epoch
  ColumnSet forward_columns_ = 0;      // of every epoch but the last
  ColumnSet backward_columns_ = 0;     // of every epoch but the first
  ColumnSet cluster_columns_ = 0;      // of every inner node of clusters, in every epoch
  std::size_t capacity_ = 0;
  SamplerOptions sampler_;
  int max_level_ = kMaxLevel;
  std::string id_index_;
};

}  // namespace octocosm
