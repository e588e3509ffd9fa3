// A dataset store opened for use: the page-file store plus what the octree
// needs to interpret it (each epoch's cube, the node capacity, the depth
// limit), read from the manifest's dataset metadata written by ingest
// (index/dataset_manifest.h).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "index/block_codec.h"
#include "index/cube.h"
#include "index/dataset_manifest.h"
#include "index/morton.h"
#include "index/sampler.h"
#include "storage/store_reader.h"

namespace octocosm {

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

class Dataset {
 public:
  // Opens the store at `directory`; throws Error (kCorruption when the
  // dataset metadata is missing or malformed, as StoreReader::Open otherwise).
  static Dataset Open(const std::string& directory);

  const StoreReader& store() const { return store_; }
  std::uint32_t epoch_count() const { return store_.epoch_count(); }
  // The dataset metadata as ingest wrote it.
  const DatasetManifest& manifest() const { return manifest_; }
  const Cube& cube(std::uint32_t epoch) const { return manifest_.epochs.at(epoch).cube; }
  std::uint64_t points(std::uint32_t epoch) const { return summary(epoch).points; }
  const EpochSummary& summary(std::uint32_t epoch) const { return manifest_.epochs.at(epoch).summary; }
  // The columns some block of some epoch carries.
  ColumnSet columns() const {
    return every_epoch_columns_ | forward_columns_ | backward_columns_ | cluster_columns_;
  }
  std::size_t capacity() const { return manifest_.capacity; }
  // The subselection's settings the store was built with.
  const SamplerOptions& sampler() const { return manifest_.sampler; }
  int max_level() const { return manifest_.max_level; }
  // The columns every block of `epoch` carries, as the manifest declares them.
  ColumnSet columns(std::uint32_t epoch) const;
  // The columns that the block of every inner node whose points are clusters
  // (index/aggregator.h) carries besides columns(epoch), in every epoch: the
  // blobs' shapes (the manifest's has_shape) and, in a dataset with
  // velocities, the velocity dispersion (has_velocity_dispersion), and the
  // links to the children's points (has_cluster_links). Leaves, and inner
  // nodes whose points are a sample, lack them.
  ColumnSet cluster_columns() const { return cluster_columns_; }
  // How `epoch` links to the next; empty for the last epoch and for a series
  // without IDs.
  const std::optional<EpochLink>& link_to_next(std::uint32_t epoch) const { return manifest_.epochs.at(epoch).to_next; }
  // The scale factor of the epoch's snapshot: its recorded time, where the
  // snapshot's header says the run is cosmological; empty otherwise.
  const std::optional<double>& scale_factor(std::uint32_t epoch) const { return scale_factors_.at(epoch); }
  // FractionalEpochAt over this store's epochs.
  double FractionalEpochAt(const PhysicalTime& time) const;
  bool has_id_index() const { return !id_index_.empty(); }
  // The directory of the ID index store (empty when the dataset has no IDs).
  const std::string& id_index_directory() const { return id_index_; }
  // "STORE/FILE (epoch N) block rXXXX", the store a directory or a URL: how
  // errors name a block.
  std::string Where(std::uint32_t epoch, NodeKey key) const;

 private:
  explicit Dataset(StoreReader store) : store_(std::move(store)) {}

  StoreReader store_;
  DatasetManifest manifest_;
  std::vector<std::optional<double>> scale_factors_;
  ColumnSet every_epoch_columns_ = 0;  // the columns of every epoch
  ColumnSet forward_columns_ = 0;      // of every epoch but the last
  ColumnSet backward_columns_ = 0;     // of every epoch but the first
  ColumnSet cluster_columns_ = 0;      // of every inner node of clusters, in every epoch
  std::string id_index_;
};

}  // namespace octocosm
