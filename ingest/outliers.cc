#include "ingest/outliers.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "base/error.h"
#include "base/hash.h"
#include "base/progress.h"
#include "index/cube.h"
#include "storage/coding.h"

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

PositionSurvey::PositionSurvey(std::size_t sample_points) : capacity_(std::max<std::size_t>(sample_points, 1)) {
  sample_.reserve(std::min<std::size_t>(capacity_, 4096));
}

namespace {

// A particle's sampling key: its index, hashed (a bijection, so no two
// particles share a key).
constexpr std::uint64_t kSampleSeed = 0x6f63746f636f736dull;
std::uint64_t SampleKey(std::uint64_t index) { return MixBits64(index ^ kSampleSeed); }

// An encoded survey: u64 capacity, u64 count, f64 mass, f64 lo[3], f64
// hi[3], u64 entries; then each entry's u64 key and f64 position[3].
constexpr std::size_t kEncodedHeader = 8 * 10, kEncodedEntry = 8 * 4;

}  // namespace

void PositionSurvey::Offer(std::uint64_t key, const double* position) {
  const auto by_key = [](const Sampled& a, const Sampled& b) { return a.key < b.key; };
  if (sample_.size() < capacity_) {
    sample_.push_back({key, {position[0], position[1], position[2]}});
    if (sample_.size() == capacity_) std::make_heap(sample_.begin(), sample_.end(), by_key);
    return;
  }
  if (key >= sample_.front().key) return;
  std::pop_heap(sample_.begin(), sample_.end(), by_key);
  sample_.back() = {key, {position[0], position[1], position[2]}};
  std::push_heap(sample_.begin(), sample_.end(), by_key);
}

void PositionSurvey::Add(const ParticleChunk& chunk, std::uint64_t first_index) {
  bounds_.Add(chunk);
  for (std::size_t i = 0; i < chunk.size(); ++i) Offer(SampleKey(first_index + i), &chunk.position[3 * i]);
}

void PositionSurvey::Add(const ParticleChunk& chunk, std::span<const std::uint64_t> indices) {
  if (indices.size() != chunk.size()) {
    throw std::logic_error("PositionSurvey::Add: " + std::to_string(indices.size()) + " indices for " +
                           std::to_string(chunk.size()) + " particles");
  }
  bounds_.Add(chunk);
  for (std::size_t i = 0; i < chunk.size(); ++i) Offer(SampleKey(indices[i]), &chunk.position[3 * i]);
}

void PositionSurvey::Merge(const PositionSurvey& other) {
  if (other.bounds_.empty()) return;
  for (int a = 0; a < 3; ++a) {
    bounds_.lo[a] = std::min(bounds_.lo[a], other.bounds_.lo[a]);
    bounds_.hi[a] = std::max(bounds_.hi[a], other.bounds_.hi[a]);
  }
  bounds_.count += other.bounds_.count;
  bounds_.mass += other.bounds_.mass;
  for (const Sampled& s : other.sample_) Offer(s.key, s.position.data());
}

Bytes PositionSurvey::Encode() const {
  Bytes out(kEncodedHeader + kEncodedEntry * sample_.size());
  std::uint8_t* p = out.data();
  PutU64(p, capacity_);
  PutU64(p + 8, bounds_.count);
  PutF64(p + 16, bounds_.mass);
  for (int a = 0; a < 3; ++a) {
    PutF64(p + 24 + 8 * a, bounds_.lo[a]);
    PutF64(p + 48 + 8 * a, bounds_.hi[a]);
  }
  PutU64(p + 72, sample_.size());
  p += kEncodedHeader;
  // In key order, so that equal surveys are equal bytes.
  std::vector<Sampled> sorted = sample_;
  std::sort(sorted.begin(), sorted.end(), [](const Sampled& a, const Sampled& b) { return a.key < b.key; });
  for (const Sampled& s : sorted) {
    PutU64(p, s.key);
    for (int a = 0; a < 3; ++a) PutF64(p + 8 + 8 * a, s.position[a]);
    p += kEncodedEntry;
  }
  return out;
}

PositionSurvey PositionSurvey::Decode(const Bytes& bytes) {
  const std::uint8_t* p = bytes.data();
  const bool whole = bytes.size() >= kEncodedHeader && (bytes.size() - kEncodedHeader) % kEncodedEntry == 0;
  if (!whole || GetU64(p) == 0 || (bytes.size() - kEncodedHeader) / kEncodedEntry != GetU64(p + 72) ||
      GetU64(p + 72) > GetU64(p)) {
    throw Error::Corruption("a position survey sent between ranks",
                            std::to_string(bytes.size()) + " bytes are not a whole survey");
  }
  PositionSurvey survey(GetU64(p));
  survey.bounds_.count = GetU64(p + 8);
  survey.bounds_.mass = GetF64(p + 16);
  for (int a = 0; a < 3; ++a) {
    survey.bounds_.lo[a] = GetF64(p + 24 + 8 * a);
    survey.bounds_.hi[a] = GetF64(p + 48 + 8 * a);
  }
  const std::size_t n = GetU64(p + 72);
  p += kEncodedHeader;
  for (std::size_t i = 0; i < n; ++i, p += kEncodedEntry) {
    const double position[3] = {GetF64(p + 8), GetF64(p + 16), GetF64(p + 24)};
    survey.Offer(GetU64(p), position);
  }
  return survey;
}

void MergeAcrossRanks(PositionSurvey& survey, RankGroup& group) {
  if (group.size() == 1) return;
  if (group.rank() != 0) {
    group.Send(0, survey.Encode());
    survey = PositionSurvey::Decode(group.Receive(0));
    return;
  }
  for (int r = 1; r < group.size(); ++r) survey.Merge(PositionSurvey::Decode(group.Receive(r)));
  const Bytes merged = survey.Encode();
  for (int r = 1; r < group.size(); ++r) group.Send(r, merged);
}

PositionBox PositionSurvey::Core() const {
  PositionBox core{bounds_.lo, bounds_.hi};
  const std::size_t m = sample_.size();
  if (m < 9) return core;
  const std::size_t k = std::min(std::max<std::size_t>(m / 1000, 4), (m - 1) / 2);
  std::vector<double> axis(m);
  for (int a = 0; a < 3; ++a) {
    for (std::size_t i = 0; i < m; ++i) axis[i] = sample_[i].position[static_cast<std::size_t>(a)];
    std::nth_element(axis.begin(), axis.begin() + static_cast<std::ptrdiff_t>(k), axis.end());
    core.lo[static_cast<std::size_t>(a)] = axis[k];
    std::nth_element(axis.begin(), axis.begin() + static_cast<std::ptrdiff_t>(m - 1 - k), axis.end());
    core.hi[static_cast<std::size_t>(a)] = axis[m - 1 - k];
  }
  return core;
}

PositionSurvey SurveyPositions(ParticleSource& source, const std::string& progress_label, RankGroup* group) {
  const std::uint64_t ranks = group != nullptr ? static_cast<std::uint64_t>(group->size()) : 1;
  const std::uint64_t rank = group != nullptr ? static_cast<std::uint64_t>(group->rank()) : 0;
  PositionSurvey survey;
  Progress progress(progress_label, source.header().total_count / ranks, "points");
  const PositionsOnlyReads positions_only(source);
  ParticleChunk chunk;
  ReadShare(source, ranks, rank, chunk, [&](const ParticleChunk& batch, std::uint64_t first_index) {
    survey.Add(batch, first_index);
    progress.Add(batch.size());
  });
  progress.Finish();
  source.Rewind();
  if (group != nullptr) MergeAcrossRanks(survey, *group);
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
