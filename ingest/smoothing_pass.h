// Smoothing lengths for every particle of a snapshot, out of core: the
// snapshot's own where its chunks carry them (ParticleChunk::smoothing > 0:
// GADGET's HSML, HDF5 SmoothingLength, unless ReadOptions::read_smoothing is
// off), and
// otherwise the radius holding each particle's k nearest neighbours
// (index/neighbour_radius.h), exact, across region borders and, in a periodic
// box, across its faces. The ground truth (`octocosm render --reference`) and
// the leaves of a store (`octocosm ingest`) both take them from here, so a
// full-detail rendering and the reference draw the same blobs.
//
// How, in bounded memory:
//   1. Regions. When the particles fit in the budget (about 48 bytes each)
//      the whole domain is one region. Otherwise a pass finds the bounds (in
//      a non-periodic snapshot), a second counts particles on a 128^3 grid,
//      and the domain is cut into octree cells of at most a quarter of the
//      budget's particles each.
//   2. Loads. Each region is loaded with a halo: its box widened by twice the
//      mean spacing of k particles at the region's density, taking periodic
//      images across the faces. Regions that fit together are loaded from
//      one read of the snapshot; otherwise one read distributes every
//      particle into the files of the regions and halos holding it (in
//      `temp_dir`), and each region is read back alone.
//   3. Search. Each region's particles get their radius against what was
//      loaded. A radius is kept only when its sphere lies inside the load
//      (or reaches past the data's edge in a non-periodic snapshot): then no
//      particle outside the load can be nearer, and the radius is exact.
//   4. The rest (sparse particles near a region's edge) are searched again
//      against everything inside their spheres, which hold their true k
//      nearest neighbours; one more read of the snapshot for as many of them
//      as fit.
// Every read asks the source for positions only (ParticleSource::
// SetPositionsOnly). Processes that share the pass (SmoothingPassOptions::
// group) each read a share of the snapshot's batches in every pass: they
// combine their bounds and counts, and send each particle to the processes
// whose loads hold it; each searches only its own regions' particles, and
// sends each length to the process that reads its particle's batch.
// With fewer than k particles in all, the radius is the one that holds all
// of them.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "index/neighbour_radius.h"
#include "ingest/rank_group.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

struct SmoothingPassOptions {
  int neighbours = kDefaultNeighbours;  // k, >= 1
  // > 0: the particles live in the periodic box [box_origin, box_origin +
  // box_size)^3 and are wrapped into it (as ingest stores them); neighbours
  // are found across its faces.
  double box_size = 0;
  std::array<double, 3> box_origin{0, 0, 0};
  std::uint64_t memory_budget = 0;     // bytes for particles held at once; 0 = 1 GiB
  std::string temp_dir;                // parent of the temporary files; "" = $TMPDIR or /tmp
  unsigned threads = 0;                // 0 = all cores
  bool quiet = false;                  // no progress bars
  // A pass shared by the processes of `group` (ingest over MPI ranks; null,
  // or a group of one: this process alone), every one of which calls it:
  // each reads every size()-th batch of the snapshot from its rank()-th,
  // searches only the regions of its share of the particles (consecutive in
  // space, about equal in particles; the domain is always cut into
  // regions), and sends each length it finds to the process that reads the
  // particle's batch. A process's table holds the lengths of the batches it
  // reads, as one process's does, and 0 for the rest (never written: in a
  // mapped table, no disk either).
  RankGroup* group = nullptr;
};

struct SmoothingPassReport {
  std::uint64_t particles = 0;
  std::uint64_t given = 0;       // taken from the snapshot
  std::uint64_t searched = 0;    // computed from neighbours
  std::uint64_t searched_again = 0;  // of those, searched a second time (step 4)
  std::uint64_t regions = 0;
  int reads = 0;                 // passes over the snapshot
  bool spilled = false;          // regions went through temporary files
  double seconds = 0;
};

// One smoothing length (float, input length units, > 0) per particle, in the
// order the source hands them out. In memory when it is small next to the
// budget, else in a temporary file mapped into memory (unlinked at once, so
// nothing stays on disk whatever happens to the process).
class SmoothingLengthTable {
 public:
  SmoothingLengthTable(std::uint64_t size, std::uint64_t memory_budget, const std::string& temp_dir);
  ~SmoothingLengthTable();
  SmoothingLengthTable(const SmoothingLengthTable&) = delete;
  SmoothingLengthTable& operator=(const SmoothingLengthTable&) = delete;

  std::uint64_t size() const { return size_; }
  float* data() { return data_; }
  const float* data() const { return data_; }
  float operator[](std::uint64_t i) const { return data_[i]; }
  bool mapped() const { return mapped_; }

 private:
  std::uint64_t size_;
  float* data_ = nullptr;
  bool mapped_ = false;
  std::unique_ptr<float[]> owned_;
};

// Runs the pass over `source` (rewound first, and left rewound). Throws
// Error::InvalidArgument on bad options, Error::BadInput when the snapshot
// holds no particles, and the readers' and the temporary files' errors.
std::unique_ptr<SmoothingLengthTable> ComputeSmoothingLengths(ParticleSource& source,
                                                              const SmoothingPassOptions& options,
                                                              SmoothingPassReport* report = nullptr);

// A source that hands out `inner`'s particles with their smoothing lengths
// from `table` (which must have come from the same source and read options).
// It maps no segments (MappableSegments() is empty), so a reader copies its
// chunks and keeps the column.
std::unique_ptr<ParticleSource> WithSmoothingLengths(std::unique_ptr<ParticleSource> inner,
                                                     std::shared_ptr<const SmoothingLengthTable> table);

}  // namespace octocosm
