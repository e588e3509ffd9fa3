// A snapshot with the particles outside a box left out: what ingest reads
// under --clip-box, and under --drop-outliers where an epoch has outliers
// (ingest/outliers.h). Everything after it (the smoothing pass, the
// sort by ID, the bounds, the chunks) sees only the particles kept, so their
// counts, masses and links agree with each other without knowing of it.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "ingest/outliers.h"
#include "ingest/rank_group.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

class ClippedSource : public ParticleSource {
 public:
  // Reads `inner` once to count what is kept, so that header() states the
  // kept particles (counts per type, total), as the smoothing pass and the
  // chunker expect; the header's `extra` gains an entry in "dropped" (the
  // box, `reason`, the particles read and dropped). Throws Error::BadInput
  // naming the file when the box keeps no particle. With a group, this rank
  // counts only its share of the batches (every size()-th from the
  // rank()-th) and the ranks add up what they counted, so every rank holds
  // the counts and the survey of the whole snapshot.
  ClippedSource(std::unique_ptr<ParticleSource> inner, const PositionBox& box, const std::string& reason,
                RankGroup* group = nullptr);

  const SnapshotHeader& header() const override { return header_; }
  bool Next(ParticleChunk& chunk) override;
  void Rewind() override { inner_->Rewind(); }
  void SetPositionsOnly(bool positions_only) override { inner_->SetPositionsOnly(positions_only); }
  // No mappable segments: a mapping would hand out the particles left out.

  std::uint64_t dropped() const { return dropped_; }
  // The largest distance of a dropped particle outside the box (PositionBox::DistanceOutside).
  double farthest_dropped() const { return farthest_dropped_; }
  // The kept particles, surveyed while they were counted.
  const PositionSurvey& survey() const { return survey_; }

 private:
  // The particles of `in` inside the box, every column, into `out`; their
  // indices in `in` into kept_.
  void Keep(const ParticleChunk& in, ParticleChunk& out);
  // The counting pass over this rank's share of the batches.
  void Count(RankGroup* group);

  std::unique_ptr<ParticleSource> inner_;
  PositionBox box_;
  SnapshotHeader header_;
  ParticleChunk read_;  // the inner source's batch, reused
  std::vector<std::uint64_t> kept_;  // Keep's indices, reused
  bool counting_ = true;  // the constructor's pass
  std::uint64_t dropped_ = 0;
  double farthest_dropped_ = 0;
  PositionSurvey survey_;
};

}  // namespace octocosm
