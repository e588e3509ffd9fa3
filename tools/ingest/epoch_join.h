// Displacements between consecutive epochs, out of core: each epoch's
// particles are sorted by ID (ExternalSorter), and a merge join of epoch e
// with epoch e + 1 gives every particle of e the offset to its own position in
// e + 1. In a periodic box the offset is the minimal image, so a particle that
// crosses the boundary moves the short way.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "index/particle_chunk.h"
#include "tools/ingest/external_sorter.h"
#include "tools/snapshot/snapshot_source.h"

namespace octocosm {

struct ParticleRecord {
  std::uint64_t key;  // the particle ID
  double position[3];
  double mass;
  float velocity[3];
  std::uint8_t type;
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
  // Reads `source` once (it must carry IDs). `run_records` bounds memory.
  SortedEpoch(ParticleSource& source, const std::string& temp_prefix, std::size_t run_records,
              const std::function<void(std::uint64_t)>& on_points);

  const Bounds& bounds() const { return bounds_; }
  bool has_velocity() const { return has_velocity_; }
  std::uint64_t duplicate_ids() const { return duplicate_ids_; }
  const ExternalSorter<ParticleRecord>& sorter() const { return sorter_; }

 private:
  ExternalSorter<ParticleRecord> sorter_;
  Bounds bounds_;
  bool has_velocity_ = false;
  std::uint64_t duplicate_ids_ = 0;
};

struct JoinStats {
  std::uint64_t matched = 0;
  std::uint64_t missing_in_next = 0;  // particles of the current epoch whose ID the next one lacks (offset 0)
};

// Calls `consume` with batches of at most `batch_points` particles of
// `current`, in ID order, each with its displacement column filled.
// box_size > 0 applies the minimal-image convention.
JoinStats JoinedPass(const SortedEpoch& current, const SortedEpoch* next, double box_size, std::size_t batch_points,
                     const std::function<void(const ParticleChunk&)>& consume);

}  // namespace octocosm
