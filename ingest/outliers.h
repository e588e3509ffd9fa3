// Outliers that would cost the bulk of a snapshot its precision.
//
// Where ingest takes an epoch's cube from its particles' bounding box, a few
// particles far from the rest set that cube, and the finest grid anything is
// placed on (index/cube.h: 2^kFinestGridBits cells per axis) is cut across
// the far points' extent: one particle at 3 x 10^38 among others within 10^4
// makes every other particle fall into one finest cell. So ingest looks at
// the positions first (PositionSurvey: exact bounds and a bounded uniform
// sample, in one streaming pass), finds the bulk from quantiles of the
// sample, and refuses the epoch (JudgeOutliers, RefuseOutliers) where the
// bulk would lose its precision. docs/INGEST.md states the rule for users.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "index/particle_chunk.h"
#include "ingest/epoch_join.h"
#include "ingest/rank_group.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

// An axis-aligned box, bounds included on both sides.
struct PositionBox {
  std::array<double, 3> lo{0, 0, 0};
  std::array<double, 3> hi{0, 0, 0};

  bool Holds(const double* point) const;
  // How far `point` lies outside the box: its largest distance on one axis (0 inside).
  double DistanceOutside(const double* point) const;
  double LargestExtent() const;
  // "[x0, y0, z0] to [x1, y1, z1]"
  std::string ToString() const;
  // Throws Error::InvalidArgument naming `flag` unless every bound is finite and lo <= hi.
  void Validate(const std::string& flag) const;
};

// The sample that finds the bulk: 2^16 positions (2 MiB with their keys) place the 0.1 %
// quantiles to within about 0.01 % of the particles, whatever their number.
inline constexpr std::size_t kSurveySamplePoints = std::size_t{1} << 16;

// Positions seen in streaming passes: their exact bounds (and count and
// mass, as Bounds) and a uniform sample of at most `sample_points` of them.
// A particle is sampled by its index in the snapshot's reading order: the
// `sample_points` particles whose indices hash lowest (bottom-k sampling), so
// that the sample depends on which particles were seen and never on who saw
// them or in what order. Ranks that each survey a share of a snapshot and
// then Merge their surveys hold what one survey of the whole would: the same
// bounds, count and sample (the mass, a float sum, to rounding).
class PositionSurvey {
 public:
  explicit PositionSurvey(std::size_t sample_points = kSurveySamplePoints);
  // The particles of `chunk`, particle i at index first_index + i.
  void Add(const ParticleChunk& chunk, std::uint64_t first_index);
  // The particles of `chunk`, particle i at index indices[i].
  void Add(const ParticleChunk& chunk, std::span<const std::uint64_t> indices);
  // Adds what `other` surveyed (particles this survey has not seen).
  void Merge(const PositionSurvey& other);
  const Bounds& bounds() const { return bounds_; }
  // The core: per axis, from the sample's k-th smallest to its k-th largest
  // coordinate, k a thousandth of the sample but at least 4 (while the
  // sample holds at least 9): the 0.1 % and 99.9 % quantiles, and for small
  // sets at least the four most extreme particles per side left out.
  PositionBox Core() const;

  // The survey as bytes (equal surveys, equal bytes), and back (for ranks
  // to send one another).
  Bytes Encode() const;
  static PositionSurvey Decode(const Bytes& bytes);

 private:
  struct Sampled {
    std::uint64_t key;  // the hash of the particle's index
    std::array<double, 3> position;
  };
  void Offer(std::uint64_t key, const double* position);

  std::size_t capacity_;
  std::vector<Sampled> sample_;  // a max-heap by key once full
  Bounds bounds_;
};

// Every rank's survey merged, on every rank (rank 0 merges and sends the
// result back, so no rank holds more than two surveys at once).
void MergeAcrossRanks(PositionSurvey& survey, RankGroup& group);

// Reads `source` once, from the start, into a survey. With a group, this
// rank reads only its share of the batches (every size()-th from the
// rank()-th, skipping the others) and the ranks' surveys are merged: every
// rank then holds the survey of the whole snapshot.
PositionSurvey SurveyPositions(ParticleSource& source, const std::string& progress_label,
                               RankGroup* group = nullptr);

// Finest cells of the full bounding cube below which the bulk's typical
// spacing may not fall: 2^10, so that positions in the bulk keep ten bits
// (a thousandth of the spacing) below the distance between neighbours.
inline constexpr double kMinFinestCellsPerSpacing = 1024;

struct OutlierVerdict {
  bool outliers = false;  // the bulk would lose its precision: refuse, or drop what lies outside `bulk`
  PositionBox core;       // PositionSurvey::Core
  // The core widened by its largest extent on every side: where the bulk
  // lies, tails included; what --drop-outliers keeps.
  PositionBox bulk;
  double cube_size = 0;    // the bounding cube of every particle (Cube::FromBounds)
  double finest_cell = 0;  // cube_size / 2^kFinestGridBits
  double spacing = 0;      // the core's typical spacing: its largest extent / cbrt(particles)
};

// The rule: outliers when finest_cell * kMinFinestCellsPerSpacing > spacing,
// that is, when the finest grid of the cube the outliers stretch is too
// coarse to keep neighbouring particles of the bulk apart to a thousandth of
// their distance. The bulk's own cube would give it 2^37 cells across; the
// outliers cost it log2(cube / core extent) bits of them. So data whose cube
// is at most 100 times their core keep more than 2^30 / cbrt(N) cells per
// spacing and are never refused below 10^18 particles, and far points that
// still leave the bulk its ten bits are taken (a 100 m laser scan of 10^6
// points with a few points 1000 km away keeps 2^17 cells per spacing). A core
// of extent 0 (all but a few particles at one point) has no precision to
// lose and is never refused.
OutlierVerdict JudgeOutliers(const PositionSurvey& survey);

// Throws Error::BadInput naming the snapshot's file(s): how many particles
// lie outside the verdict's bulk and how far, the bulk, and the ways out.
[[noreturn]] void RefuseOutliers(const SnapshotHeader& header, const OutlierVerdict& verdict, std::uint64_t outside,
                                 double farthest);

}  // namespace octocosm
