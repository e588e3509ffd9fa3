// The part of a ParticleSource that every format shares: walking a list of
// contiguous runs of particles ("segments": one particle type in one file) in
// chunk-sized steps, and rejecting values the octree cannot take (non-finite
// coordinates or velocities, masses that are not finite and > 0, smoothing
// lengths that are not finite and >= 0, positions outside the periodic box
// by more than kPeriodicBoxTolerance), naming the file and the particle
// rather than failing deep in the build. A format supplies only
// AppendRange(), which reads part of one segment.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

struct Segment {
  std::size_t file = 0;     // index into header().files
  int type = 0;             // particle type
  std::uint64_t count = 0;  // particles in the run
};

class SegmentedSource : public ParticleSource {
 public:
  const SnapshotHeader& header() const override { return header_; }
  bool Next(ParticleChunk& chunk) override;
  void Rewind() override;
  std::uint64_t Skip() override;
  void SetPositionsOnly(bool positions_only) override { positions_only_ = positions_only; }

 protected:
  explicit SegmentedSource(std::size_t chunk_particles);

  // Appends particles [begin, begin + count) of `segment` to `chunk`: position,
  // mass and type always, smoothing exactly when the header says so, and
  // velocity and id exactly when FillsVelocity() and FillsId() say so.
  // Calls for one segment come in increasing order of `begin` until
  // Rewind().
  virtual void AppendRange(const Segment& segment, std::uint64_t begin, std::size_t count,
                           ParticleChunk& chunk) = 0;
  // Called by Rewind() so that a format can reset its own stream position.
  virtual void OnRewind() {}
  // Whether AppendRange may skip particles (its `begin` jump ahead): false
  // for a format read as one stream, which Skip() then reads through.
  virtual bool SeeksRanges() const { return true; }
  // Names particle `index` of `segment` in messages, e.g. "PartType1 particle 7".
  virtual std::string DescribeParticle(const Segment& segment, std::uint64_t index) const;
  // Names where `segment`'s smoothing lengths come from in messages, e.g.
  // "block HSML"; asked only of a source whose header has them.
  virtual std::string DescribeSmoothing(const Segment& segment) const;

  // Whether AppendRange fills velocities and IDs: when the header has them
  // and no pass asked for positions only.
  bool FillsVelocity() const { return header_.has_velocity && !positions_only_; }
  bool FillsId() const { return header_.has_id && !positions_only_; }
  bool PositionsOnly() const { return positions_only_; }

  // Fills header_.count_per_type / total_count from segments_ (call once at open).
  void CountSegments(std::size_t type_count);
  // Sets header_.box_size: the options' box (box_size_override, ignore_box)
  // when they give one, else `declared`, the header's `field` of file
  // `path`, which must be finite and >= 0 (BadInput otherwise). Next() then
  // refuses particles outside the box by more than kPeriodicBoxTolerance.
  void SetBoxSize(const std::string& path, const std::string& field, double declared, const ReadOptions& options);

  SnapshotHeader header_;
  std::vector<Segment> segments_;

 private:
  void CheckValues(const Segment& segment, std::uint64_t begin, const ParticleChunk& chunk,
                   std::size_t first) const;

  std::string box_from_;  // where header_.box_size came from, for messages
  std::size_t chunk_particles_;
  bool positions_only_ = false;
  std::size_t segment_index_ = 0;
  std::uint64_t segment_offset_ = 0;
};

// Returns `value` when it is finite; else throws Error::BadInput naming
// `path` and the header field `field` ("header field time").
double RequireFinite(const std::string& path, const std::string& field, double value);

// True when `type` is among `selected` (an empty selection takes every type).
bool IsTypeSelected(const std::vector<int>& selected, int type);

// Reconciles the per-type totals a snapshot header declares with the per-type
// sums of the per-file counts, and returns the totals to use. Real files have
// all-zero totals (only per-file counts filled) and junk in the high words, so:
//  * totals all zero -> the file sums (extra["totals_from_file_counts"] = true);
//  * low + high<<32 equals the sum -> fine;
//  * low word alone equals the sum -> fine, high word ignored (recorded in
//    extra["ignored_total_high_words"]);
//  * anything else throws Error::BadInput naming `path` and the type.
// `high` may be empty (no high-word field).
std::vector<std::uint64_t> ReconcileTypeTotals(const std::string& path, const std::vector<std::uint64_t>& low,
                                               const std::vector<std::uint64_t>& high,
                                               const std::vector<std::uint64_t>& file_sums,
                                               nlohmann::json& extra);

}  // namespace octocosm
