// Links between consecutive epochs, out of core. Each epoch's particles are
// sorted by ID (ExternalSorter), and a merge join of epoch e with epoch e + 1
// gives every particle of e its displacement to its own position in e + 1 and
// its velocity there. The same join, walking e + 1's particles in ID order,
// writes for each of them the way back (minus that displacement, and the
// velocity in e) to a "link file", which e + 1's own join then reads in step
// with its particles. So each epoch is sorted once, at most two sorted epochs
// are open at a time, and the way back costs a sequential file of 32 bytes
// per particle instead of a third sorted epoch.
//
// In a periodic box the offset is the minimal image, so a particle that
// crosses the boundary moves the short way, forward and back.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "index/particle_chunk.h"
#include "ingest/external_sorter.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

struct ParticleRecord {
  std::uint64_t key;  // the particle ID
  double position[3];
  double mass;
  float velocity[3];
  std::uint8_t type;
};

// A particle's smoothing length, sorted by ID beside its ParticleRecord when
// the epoch carries them (ParticleChunk::smoothing): a sorter of its own
// rather than a wider ParticleRecord (56 bytes would become 64), so that an
// epoch without them sorts what it sorted before. Both sorters are stable
// and take the particles in the same order, so their k-th records belong to
// the same particle, duplicate IDs included.
struct SmoothingRecord {
  std::uint64_t key;  // the particle ID
  float smoothing;
};

struct Bounds {
  std::array<double, 3> lo{1e300, 1e300, 1e300};
  std::array<double, 3> hi{-1e300, -1e300, -1e300};
  std::uint64_t count = 0;
  double mass = 0;

  void Add(const ParticleChunk& chunk);
  bool empty() const { return count == 0; }
};

// One epoch's particles in ID order.
class SortedEpoch {
 public:
  // Reads `source` once (it must carry IDs). `run_records` ParticleRecords
  // bound memory; with smoothing lengths, fewer of them and as many
  // SmoothingRecords share that room.
  SortedEpoch(ParticleSource& source, const std::string& temp_prefix, std::size_t run_records,
              const std::function<void(std::uint64_t)>& on_points);

  const Bounds& bounds() const { return bounds_; }
  bool has_velocity() const { return has_velocity_; }
  bool has_smoothing() const { return smoothing_sorter_ != nullptr; }
  std::uint64_t duplicate_ids() const { return duplicate_ids_; }
  // The first repeated ID in ID order, for messages; meaningful when duplicate_ids() > 0.
  std::uint64_t first_duplicate_id() const { return first_duplicate_id_; }
  const ExternalSorter<ParticleRecord>& sorter() const { return sorter_; }
  // The particles' smoothing lengths, in the order of sorter()'s records;
  // only when has_smoothing().
  const ExternalSorter<SmoothingRecord>& smoothing_sorter() const { return *smoothing_sorter_; }

 private:
  ExternalSorter<ParticleRecord> sorter_;
  std::unique_ptr<ExternalSorter<SmoothingRecord>> smoothing_sorter_;
  Bounds bounds_;
  bool has_velocity_ = false;
  std::uint64_t duplicate_ids_ = 0;
  std::uint64_t first_duplicate_id_ = 0;
};

// The Hermite velocity scale of an epoch pair. A renderer draws a particle
// between epochs e and e + 1 on the cubic Hermite curve from p_e to p_e+1
// with tangents s v_e and s v_e+1; s converts velocity units into position
// units per epoch step, which snapshots do not state reliably (code units,
// the sqrt(a) convention of cosmological runs, a length unit missing from the
// header). So s is fitted, unit-free, from the trapezoid rule d ~ s vbar with
// vbar = (v_e + v_e+1) / 2 and d the displacement.
//
// The plain least-squares fit over every matched particle,
// s_ls = sum(d . vbar) / sum(vbar . vbar), is recorded, but it is not the
// scale: where snapshots are further apart than some orbits take to curve
// (the shared GADGET-4 galaxy collision: a step of 0.5 time units, ~490 Myr),
// the trapezoid rule fails for those particles, and they drag s_ls far from
// the step (0.31-0.42 for steps of 0.50-0.51 there; a particle half an orbit
// on even points against its velocity). Such particles are hopeless for any
// s, so the scale is fitted where the rule holds: each particle has its own
// scale s_i = (d . vbar) / (vbar . vbar); a histogram of s_i in 1/8-octave
// bins, weighted by vbar . vbar, finds the mode (the heaviest three adjacent
// bins), and s is the least-squares fit over the particles within two bins
// of it (about +-25 %). Where every particle moves nearly straight, s = s_ls.
// On the galaxy series s comes out within 3 % of the step for 19 of 20
// pairs and 16 % above it for one (tests/ingest/ingest_shared_data_test.cc).
//
// The fit residual r = sqrt(sum |d - s vbar|^2 / sum |d|^2), over every
// matched particle, says how well the Hermite curves with this s reproduce
// the displacements overall; inlier_fraction is the weight share that
// agrees with s. Without velocities, with all-zero velocities or all-zero
// displacements, s = s_ls = 0 and r = 1.
class VelocityScaleFit {
 public:
  VelocityScaleFit();
  void Add(const double displacement[3], const float velocity[3], const float next_velocity[3]);

  double velocity_scale() const;
  double least_squares_scale() const;
  double fit_residual() const;
  double inlier_fraction() const;

 private:
  static constexpr int kBinsPerOctave = 8;
  static constexpr int kOctaves = 128;  // |s_i| from 2^-64 to 2^64; beyond, the end bins
  static constexpr int kBins = kBinsPerOctave * kOctaves;
  static constexpr int kInlierBins = 2;  // on each side of the mode
  struct Bin {
    double vv = 0, dv = 0;
  };
  // The bins around the mode: [first, last) of bins_.
  std::pair<std::size_t, std::size_t> InlierBins() const;
  bool Fitted() const { return sum_vv_ > 0 && sum_dd_ > 0; }

  // Positive s_i in bins [0, kBins), negative in [kBins, 2 kBins) (a series
  // in reverse time order has a negative scale).
  std::vector<Bin> bins_;
  // Sums in double: their relative rounding error stays far below any
  // residual worth reporting, even over 10^9 particles.
  double sum_dv_ = 0, sum_vv_ = 0, sum_dd_ = 0;
};

struct JoinStats {
  std::uint64_t matched = 0;          // particles of the current epoch found in the next
  std::uint64_t missing_in_next = 0;  // particles of the current epoch whose ID the next one lacks (zeros)
  std::uint64_t new_in_next = 0;      // particles of the next epoch whose ID the current one lacks
  VelocityScaleFit fit;               // over the matched particles, when the epochs carry velocities
  double max_displacement = 0;        // the largest |d| of a matched particle
  double max_speed_sum = 0;           // the largest |v_e| + |v_e+1| of a matched particle
};

// Calls `consume` with batches of at most `batch_points` particles of
// `current`, in ID order, with their smoothing lengths when `current` has
// them, and the epoch links filled:
//  - with `next`: displacement (and next_velocity, with velocities) from the
//    join, and the link file `links_to_next` written for the next epoch;
//  - with `links_from_previous` (the file the previous epoch's join wrote;
//    "" for the first epoch): prev_displacement (and prev_velocity).
// Particles absent from the neighbouring epoch get zeros. box_size > 0
// applies the minimal-image convention. May be called again: each call
// rewrites `links_to_next` from the start.
JoinStats JoinedPass(const SortedEpoch& current, const SortedEpoch* next, const std::string& links_from_previous,
                     const std::string& links_to_next, double box_size, std::size_t batch_points,
                     const std::function<void(const ParticleChunk&)>& consume);

}  // namespace octocosm
