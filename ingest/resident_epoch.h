// An epoch's points held in memory whole while its chunks are built
// (Chunker::SplitResident), each column as narrow as its values allow:
//  - positions as float while every coordinate is exactly a float (GADGET
//    and raw f32 snapshots store them so, and most HDF5 ones), else double;
//  - masses as one value per particle type while all particles of a type
//    weigh the same (a GADGET header's mass table), else one per particle;
//  - particle IDs as 32 bits while all are below 2^32, else 64.
// Smoothing lengths, when the points carry them, are kept as they come (a
// float each) and the vector columns likewise.
// A column whose values stop fitting is widened once, its earlier values
// copied over exactly; reading a point gives back exactly what was appended.
//
// Why: this is the only memory an ingest fills that grows with the whole
// epoch, and on the virtual machines this runs on the first touch of fresh
// memory is the read's largest cost (PageWarmer, base/page_warmer.h).
// Narrow, a GADGET point with velocity and ID takes 29 bytes instead of 53.
//
// Better still, an epoch whose files hold every column as a plain array in
// this machine's byte order (GADGET files written on a little-endian machine
// with float positions and a mass table) is not copied at all: Map() maps
// the files' position, velocity and ID blocks read-only and the points are
// read where they lie, in the page cache. Mapping cached pages costs a
// fraction of zeroing fresh ones and copying into them (docs/INGEST.md).
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "base/page_warmer.h"
#include "index/cube.h"
#include "index/particle_chunk.h"
#include "ingest/particle_file.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

// Values kept as Narrow while each appended Wide value converts to Narrow
// and back exactly, and as Wide from the first one that does not.
template <typename Narrow, typename Wide>
class NarrowableColumn {
 public:
  // Room for `values` narrow values, on small pages, listed in `fresh`.
  void Reserve(std::size_t values, std::vector<PageWarmer::Range>& fresh);
  void Append(std::span<const Wide> values);
  bool is_narrow() const { return !is_wide_; }
  Wide operator[](std::size_t i) const { return is_wide_ ? wide_[i] : static_cast<Wide>(narrow_[i]); }
  // The values, in the form they are kept in (the other is empty).
  const std::vector<Narrow>& narrow_values() const { return narrow_; }
  const std::vector<Wide>& wide_values() const { return wide_; }

 private:
  bool is_wide_ = false;
  std::vector<Narrow> narrow_;
  std::vector<Wide> wide_;
};

// One pass over a point set: calls `consume` for each batch, in order.
using PointPass = std::function<void(const std::function<void(const ParticleChunk&)>& consume)>;

class ResidentEpoch {
 public:
  ResidentEpoch();
  ~ResidentEpoch();
  ResidentEpoch(ResidentEpoch&&) noexcept;
  ResidentEpoch& operator=(ResidentEpoch&&) noexcept;

  // Reads `pass` whole into columns of its own: room for `expected_points`
  // (more or fewer are fine) reserved up front, their fresh pages faulted in
  // by a PageWarmer while this thread appends. Every batch must carry
  // exactly the optional columns `columns` names. Throws
  // Error::InvalidArgument beyond 2^32 - 1 points.
  void Read(const PointPass& pass, std::size_t expected_points, const ParticleColumns& columns);

  // Room for `points` in the columns `columns` names (position, mass and
  // type always), in their narrow forms, on small pages (filled once and
  // kept: base/huge_pages.h). Every appended batch must carry exactly these
  // optional columns. Returns the reserved memory, not yet touched, for a
  // PageWarmer.
  std::vector<PageWarmer::Range> Reserve(std::size_t points, const ParticleColumns& columns);

  // Appends a batch. Throws Error::InvalidArgument when its columns are not
  // the reserved ones or their lengths disagree.
  void Append(const ParticleChunk& batch);

  // Holds the points of `segments` where they lie in the files `files` (a
  // source's MappableSegments() and header().files), mapped read-only rather
  // than copied: nothing is zeroed or copied until a chunk is gathered. The
  // optional columns are those `columns` names, which may be only the ID and
  // the velocity. Returns false, the epoch left empty, where the segments
  // cannot be held so (a file that cannot be mapped or is shorter than its
  // segments, one type's masses differing between files, more than 2^32 - 1
  // points, other columns asked for, smoothing lengths among them);
  // reading through the source then does.
  // The values are not checked: see ValuesAsRead.
  bool Map(std::span<const MappableSegment> segments, std::span<const std::string> files,
           const ParticleColumns& columns);
  // Whether every position and velocity is finite and, in a periodic cube,
  // every position inside it: what reading through a source checks, and
  // what ingest's wrap into the box would change. On `threads` threads;
  // `progress` is told of the points checked, on this thread.
  bool ValuesAsRead(const Cube& cube, int threads, const std::function<void(std::size_t)>& progress) const;
  // Calls `visit` with the IDs of consecutive points, in order, until all
  // are visited. Needs the ID column.
  void VisitIds(const std::function<void(std::span<const std::uint64_t>)>& visit) const;

  std::size_t size() const { return size_; }
  const ParticleColumns& columns() const { return columns_; }
  bool mapped() const { return !mappings_.empty(); }
  // Bytes the columns take per point as they are kept now (mapped: the
  // mapped bytes of the files, averaged).
  std::size_t BytesPerPoint() const;
  bool positions_narrow() const;
  bool masses_per_type() const { return per_type_mass_; }
  bool ids_narrow() const;

  // Point i's position, absolute.
  std::array<double, 3> Position(std::size_t i) const;
  // Calls visit(i, position) for every point i in [begin, end), in order,
  // with its position (x, y, z, absolute): run by run, not a look-up of
  // point i's run as Position(i) makes.
  template <typename Visit>
  void ForEachPosition(std::size_t begin, std::size_t end, Visit&& visit) const;
  // Calls visit(k, position) for every k in order, with point listed[k]'s
  // position: stretch by stretch of listed points in one run, each read
  // where it lies and fetched a few points ahead. Indices must be below
  // size() (the caller checks).
  template <typename Visit>
  void ForEachListedPosition(std::span<const std::uint32_t> listed, Visit&& visit) const;
  // Where point i's position lies in memory, to prefetch it.
  const void* PositionAddress(std::size_t i) const;
  // to[target[k]] = point listed[k], for every column, in ParticleChunk's
  // wide form; `to` is sized to listed.size() points and its columns the
  // epoch lacks are emptied. Indices must be below size() and target must
  // be a permutation of 0..listed.size()-1 (the caller checks).
  void CopyPoints(std::span<const std::uint32_t> listed, std::span<const std::uint32_t> target,
                  ParticleChunk& to) const;

 private:
  class Mapping;
  // Consecutive points whose columns lie in one array each: the epoch's own
  // columns (one run), or one mapped segment. Columns are read with
  // unaligned loads: a mapped file's 8-byte IDs start wherever its records
  // put them.
  struct Run {
    std::size_t begin = 0, count = 0;  // points [begin, begin + count) of the epoch
    const void* position = nullptr;    // x,y,z interleaved, float or double
    bool positions_wide = false;
    const std::uint8_t* type = nullptr;  // per point, or null: all of type run_type
    std::uint8_t run_type = 0;
    const double* mass = nullptr;       // per point, or null: type_mass_ of the type
    const void* id = nullptr;
    std::size_t id_bytes = 0;           // 4 or 8
    std::array<const void*, kVectorColumnCount> vectors{};  // 3 floats a point each
    const float* smoothing = nullptr;  // per point, when the columns carry it
  };
  const Run& RunOf(std::size_t i) const;
  // Point `offset` of the run's positions, as doubles (unaligned loads: a
  // mapped file's doubles start wherever its records put them).
  static void LoadPosition(const Run& run, std::size_t offset, double* position);
  // Describes the own columns as the one run (after they change).
  void DescribeOwnColumns();
  void WidenMasses();

  ParticleColumns columns_;
  std::size_t size_ = 0;
  std::vector<Run> runs_;
  std::vector<std::uint32_t> run_of_block_;   // first run of each block of kRunBlock points
  std::vector<std::unique_ptr<Mapping>> mappings_;

  NarrowableColumn<float, double> position_;  // x,y,z interleaved
  bool per_type_mass_ = true;
  std::array<double, 256> type_mass_{};        // per type, while per_type_mass_
  std::array<bool, 256> type_mass_known_{};
  std::vector<double> mass_;                   // per point, once not per type
  std::vector<std::uint8_t> type_;
  NarrowableColumn<std::uint32_t, std::uint64_t> id_;
  std::vector<float> smoothing_;
  std::array<std::vector<float>, kVectorColumnCount> vectors_;  // indexed by VectorColumn
};

template <typename Visit>
void ResidentEpoch::ForEachPosition(std::size_t begin, std::size_t end, Visit&& visit) const {
  for (std::size_t i = begin; i < end;) {
    const Run& run = RunOf(i);
    const std::size_t run_end = std::min(end, run.begin + run.count);
    for (; i < run_end; ++i) {
      double position[3];
      LoadPosition(run, i - run.begin, position);
      visit(i, static_cast<const double*>(position));
    }
  }
}

template <typename Visit>
void ResidentEpoch::ForEachListedPosition(std::span<const std::uint32_t> listed, Visit&& visit) const {
  // Listed points lie scattered across the columns, so each read is a cache
  // miss; fetching this many points ahead lets the misses overlap.
  constexpr std::size_t kAhead = 16;
  const std::size_t n = listed.size();
  for (std::size_t k = 0; k < n;) {
    const Run& run = RunOf(listed[k]);
    std::size_t stretch_end = k + 1;
    while (stretch_end < n && listed[stretch_end] - run.begin < run.count) ++stretch_end;
    const std::size_t stride = 3 * (run.positions_wide ? sizeof(double) : sizeof(float));
    for (; k < stretch_end; ++k) {
      if (k + kAhead < stretch_end) {
        __builtin_prefetch(static_cast<const std::byte*>(run.position) + stride * (listed[k + kAhead] - run.begin));
      }
      double position[3];
      LoadPosition(run, listed[k] - run.begin, position);
      visit(k, static_cast<const double*>(position));
    }
  }
}

inline void ResidentEpoch::LoadPosition(const Run& run, std::size_t offset, double* position) {
  const auto* bytes = static_cast<const std::byte*>(run.position);
  if (run.positions_wide) {
    std::memcpy(position, bytes + 3 * sizeof(double) * offset, 3 * sizeof(double));  // need not be aligned
    return;
  }
  float narrow[3];
  std::memcpy(narrow, bytes + 3 * sizeof(float) * offset, sizeof(narrow));
  for (int a = 0; a < 3; ++a) position[a] = narrow[a];
}

}  // namespace octocosm
