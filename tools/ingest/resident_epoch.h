// An epoch's points held in memory whole while its chunks are built
// (Chunker::SplitResident), each column as narrow as its values allow:
//  - positions as float while every coordinate is exactly a float (GADGET
//    and raw f32 snapshots store them so, and most HDF5 ones), else double;
//  - masses as one value per particle type while all particles of a type
//    weigh the same (a GADGET header's mass table), else one per particle;
//  - particle IDs as 32 bits while all are below 2^32, else 64.
// A column whose values stop fitting is widened once, its earlier values
// copied over exactly; reading a point gives back exactly what was appended.
//
// Why: this is the only memory an ingest fills that grows with the whole
// epoch, and on the virtual machines this runs on the first touch of fresh
// memory is the read's largest cost (PageWarmer, tools/page_warmer.h).
// Narrow, a GADGET point with velocity and ID takes 29 bytes instead of 53.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "index/particle_chunk.h"
#include "tools/ingest/particle_file.h"
#include "tools/page_warmer.h"

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

class ResidentEpoch {
 public:
  // Room for `points` in the columns `columns` names (position, mass and
  // type always), in their narrow forms, on small pages (filled once and
  // kept: tools/huge_pages.h). Every appended batch must carry exactly these
  // optional columns. Returns the reserved memory, not yet touched, for a
  // PageWarmer.
  std::vector<PageWarmer::Range> Reserve(std::size_t points, const ParticleColumns& columns);

  // Appends a batch. Throws Error::InvalidArgument when its columns are not
  // the reserved ones or their lengths disagree.
  void Append(const ParticleChunk& batch);

  std::size_t size() const { return type_.size(); }
  const ParticleColumns& columns() const { return columns_; }
  // Bytes the columns take per point as they are kept now.
  std::size_t BytesPerPoint() const;
  bool positions_narrow() const { return position_.is_narrow(); }
  bool masses_per_type() const { return per_type_mass_; }
  bool ids_narrow() const { return id_.is_narrow(); }

  // Point i's position, absolute.
  std::array<double, 3> Position(std::size_t i) const;
  // Where point i's position lies in memory, to prefetch it.
  const void* PositionAddress(std::size_t i) const;
  // to[target[k]] = point listed[k], for every column, in ParticleChunk's
  // wide form; `to` is sized to listed.size() points and its columns the
  // epoch lacks are emptied. Indices must be below size() and target must
  // be a permutation of 0..listed.size()-1 (the caller checks).
  void CopyPoints(std::span<const std::uint32_t> listed, std::span<const std::uint32_t> target,
                  ParticleChunk& to) const;

 private:
  void WidenMasses();

  ParticleColumns columns_;
  NarrowableColumn<float, double> position_;  // x,y,z interleaved
  bool per_type_mass_ = true;
  std::array<double, 256> type_mass_{};        // per type, while per_type_mass_
  std::array<bool, 256> type_mass_known_{};
  std::vector<double> mass_;                   // per point, once not per type
  std::vector<std::uint8_t> type_;
  NarrowableColumn<std::uint32_t, std::uint64_t> id_;
  std::array<std::vector<float>, kVectorColumnCount> vectors_;  // indexed by VectorColumn
};

}  // namespace octocosm
