#include "ingest/outliers.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "base/error.h"
#include "base/hash.h"
#include "base/progress.h"
#include "index/cube.h"

namespace octocosm {
namespace {

std::string Number(double x) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", x);
  return text;
}

std::string Plural(std::uint64_t n, const char* one, const char* many) {
  return std::to_string(n) + " " + (n == 1 ? one : many);
}

}  // namespace

bool PositionBox::Holds(const double* point) const {
  for (int a = 0; a < 3; ++a) {
    if (!(point[a] >= lo[a] && point[a] <= hi[a])) return false;
  }
  return true;
}

double PositionBox::DistanceOutside(const double* point) const {
  double distance = 0;
  for (int a = 0; a < 3; ++a) distance = std::max({distance, lo[a] - point[a], point[a] - hi[a]});
  return distance;
}

double PositionBox::LargestExtent() const {
  return std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
}

std::string PositionBox::ToString() const {
  return "[" + Number(lo[0]) + ", " + Number(lo[1]) + ", " + Number(lo[2]) + "] to [" + Number(hi[0]) + ", " +
         Number(hi[1]) + ", " + Number(hi[2]) + "]";
}

void PositionBox::Validate(const std::string& flag) const {
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(lo[a]) || !std::isfinite(hi[a]) || lo[a] > hi[a]) {
      throw Error::InvalidArgument(flag + " " + ToString() +
                                   ": every bound must be finite, and each lower one at most the upper one");
    }
  }
}

PositionSurvey::PositionSurvey(std::size_t sample_points)
    : capacity_(std::max<std::size_t>(sample_points, 1)), random_state_(0x6f63746f636f736dull) {
  sample_.reserve(std::min<std::size_t>(capacity_, 4096));
}

void PositionSurvey::Add(const ParticleChunk& chunk) {
  const std::uint64_t seen_before = bounds_.count;
  bounds_.Add(chunk);
  for (std::size_t i = 0; i < chunk.size(); ++i) {
    const std::array<double, 3> p{chunk.position[3 * i], chunk.position[3 * i + 1], chunk.position[3 * i + 2]};
    const std::uint64_t seen = seen_before + i;  // particles before this one
    if (sample_.size() < capacity_) {
      sample_.push_back(p);
      continue;
    }
    // Reservoir sampling (Vitter's algorithm R): each particle stays in the
    // sample with probability capacity / (seen + 1).
    const std::uint64_t slot = SplitMix64(random_state_) % (seen + 1);
    if (slot < capacity_) sample_[slot] = p;
  }
}

PositionBox PositionSurvey::Core() const {
  PositionBox core{bounds_.lo, bounds_.hi};
  const std::size_t m = sample_.size();
  if (m < 9) return core;
  const std::size_t k = std::min(std::max<std::size_t>(m / 1000, 4), (m - 1) / 2);
  std::vector<double> axis(m);
  for (int a = 0; a < 3; ++a) {
    for (std::size_t i = 0; i < m; ++i) axis[i] = sample_[i][static_cast<std::size_t>(a)];
    std::nth_element(axis.begin(), axis.begin() + static_cast<std::ptrdiff_t>(k), axis.end());
    core.lo[static_cast<std::size_t>(a)] = axis[k];
    std::nth_element(axis.begin(), axis.begin() + static_cast<std::ptrdiff_t>(m - 1 - k), axis.end());
    core.hi[static_cast<std::size_t>(a)] = axis[m - 1 - k];
  }
  return core;
}

PositionSurvey SurveyPositions(ParticleSource& source, const std::string& progress_label) {
  PositionSurvey survey;
  Progress progress(progress_label, source.header().total_count, "points");
  const PositionsOnlyReads positions_only(source);
  source.Rewind();
  ParticleChunk chunk;
  while (source.Next(chunk)) {
    survey.Add(chunk);
    progress.Add(chunk.size());
  }
  progress.Finish();
  source.Rewind();
  return survey;
}

OutlierVerdict JudgeOutliers(const PositionSurvey& survey) {
  OutlierVerdict verdict;
  const Bounds& bounds = survey.bounds();
  if (bounds.empty()) return verdict;
  verdict.core = survey.Core();
  const double extent = verdict.core.LargestExtent();
  verdict.bulk = verdict.core;
  for (int a = 0; a < 3; ++a) {
    verdict.bulk.lo[static_cast<std::size_t>(a)] -= extent;
    verdict.bulk.hi[static_cast<std::size_t>(a)] += extent;
  }
  verdict.cube_size = Cube::FromBounds(bounds.lo, bounds.hi).size;
  verdict.finest_cell = std::ldexp(verdict.cube_size, -kFinestGridBits);
  verdict.spacing = extent / std::cbrt(static_cast<double>(bounds.count));
  verdict.outliers = extent > 0 && verdict.finest_cell * kMinFinestCellsPerSpacing > verdict.spacing;
  return verdict;
}

void RefuseOutliers(const SnapshotHeader& header, const OutlierVerdict& verdict, std::uint64_t outside,
                    double farthest) {
  const std::size_t files = header.files.size();
  const std::string where = files > 1 ? " (the snapshot's " + std::to_string(files) + " files)" : "";
  throw Error::BadInput(
      header.files.front(),
      Plural(outside, "particle lies", "particles lie") + where + " far outside the bulk of the others, up to " +
          Number(farthest) + " beyond it: the bulk (between the 0.1 % and 99.9 % quantiles per axis) spans " +
          verdict.core.ToString() + ", but a bounding cube of edge " + Number(verdict.cube_size) +
          " would have finest cells of " + Number(verdict.finest_cell) + ", too coarse for the bulk's typical spacing of " +
          Number(verdict.spacing) + " (at least " + Number(kMinFinestCellsPerSpacing) +
          " cells to a spacing): its distinct particles would lose their precision or collapse onto one point. "
          "Ways out: --drop-outliers (drop the " + Plural(outside, "particle", "particles") +
          " outside the bulk widened by its extent, " + verdict.bulk.ToString() +
          "), --clip-box X0,Y0,Z0,X1,Y1,Z1 (keep only the particles inside the box you give), or --cube x,y,z,size "
          "(index the cube you give, accepting its resolution)");
}

}  // namespace octocosm
