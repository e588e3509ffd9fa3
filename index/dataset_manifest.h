// The dataset metadata of a store written by `octocosm ingest`: what the
// octree needs to interpret the page files (each epoch's cube, the node
// capacity, the depth limit, which columns blocks carry), how epochs link,
// and what ingest counted and read. It travels as the manifest's `dataset`
// member (docs/FORMAT.md 5.2), which the manifest's checksum covers
// (storage/manifest.h); this type is the one place that writes and reads it.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "index/cube.h"
#include "index/morton.h"
#include "index/sampler.h"

namespace octocosm {

// How an epoch links to the next, as ingest fitted it (docs/FORMAT.md 5.2,
// `to_next`; ingest/epoch_join.h, VelocityScaleFit). A renderer moves a
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

// What the dataset metadata records about one epoch's tree, as ingest
// counted it while building; `verify` checks it against the blocks. Stores
// built by hand (tests) may leave out what they do not know.
struct EpochSummary {
  std::uint64_t points = 0;    // particles in the leaves
  std::optional<double> mass;  // of all particles
  std::optional<std::uint64_t> nodes;
  std::optional<std::uint64_t> leaves;
  std::optional<int> depth;    // the deepest leaf's level
};

struct EpochRecord {
  Cube cube;  // the cube the epoch's keys refer to
  EpochSummary summary;
  std::uint64_t missing_in_next = 0;  // particles whose ID the next epoch lacks
  std::uint64_t missing_in_prev = 0;  // particles whose ID the previous epoch lacks
  std::uint64_t duplicate_ids = 0;
  std::optional<EpochLink> to_next;   // every epoch but the last of a series with IDs
  // What the reader found in the snapshot's header (format, files, time,
  // redshift, box, counts, cosmology, extra), kept as read.
  nlohmann::json input = nlohmann::json::object();

  // The scale factor of the epoch's snapshot: its recorded time where the
  // header says the run is cosmological (or 1 / (1 + z) without a time).
  std::optional<double> ScaleFactor() const;

  // As the dataset manifest's epoch `epoch_number`. FromJson throws
  // nlohmann::json's exceptions for missing members or wrong types, and
  // kInvalidArgument for an impossible cube (DatasetManifest::FromJson
  // turns both into kCorruption naming the file).
  nlohmann::json ToJson(std::size_t epoch_number) const;
  static EpochRecord FromJson(const nlohmann::json& json);
};

struct DatasetManifest {
  std::string generator = "octocosm ingest";
  std::size_t capacity = 0;
  int max_level = kMaxLevel;
  std::string coarse = "clusters";  // "clusters" or "sample"
  std::string smoothing_rule = "neighbours";  // or "density grid"
  int neighbours = 32;
  SamplerOptions sampler;
  bool has_velocity = false, has_id = false;
  bool has_displacement = false, has_next_velocity = false;
  bool has_prev_displacement = false, has_prev_velocity = false;
  bool has_velocity_dispersion = false, has_shape = false;
  // Inner nodes of clusters carry child_cluster and refine_bound (index/block_codec.h).
  bool has_cluster_links = false;
  std::string id_index;  // subdirectory of the ID index, empty without IDs
  std::vector<EpochRecord> epochs;

  nlohmann::json ToJson() const;
  // Throws Error::Corruption naming `path` when a member is missing, of the
  // wrong type or impossible (a capacity of 0, a depth limit beyond
  // kMaxLevel, a cube that is not finite and positive, velocity dispersions
  // without velocities). Members a store may lack (written before they
  // existed) read as absent.
  static DatasetManifest FromJson(const nlohmann::json& json, const std::string& path);
};

}  // namespace octocosm
