#include "ingest/snapshot/segmented_source.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "base/error.h"

namespace octocosm {
namespace {

constexpr std::uint64_t kMaxParticlesPerRead = 1 << 16;

}  // namespace

SegmentedSource::SegmentedSource(std::size_t chunk_particles) : chunk_particles_(chunk_particles) {
  if (chunk_particles_ == 0) throw Error::InvalidArgument("chunk_particles must be at least 1");
}

bool SegmentedSource::Next(ParticleChunk& chunk) {
  chunk.clear();
  while (chunk.size() < chunk_particles_ && segment_index_ < segments_.size()) {
    const Segment& segment = segments_[segment_index_];
    std::uint64_t left = segment.count - segment_offset_;
    if (left == 0) {
      ++segment_index_;
      segment_offset_ = 0;
      continue;
    }
    // Reading in pieces of at most kMaxParticlesPerRead bounds the byte buffer
    // of a format (24 bytes a particle) whatever the chunk size.
    auto count = static_cast<std::size_t>(
        std::min<std::uint64_t>({left, chunk_particles_ - chunk.size(), kMaxParticlesPerRead}));
    std::size_t first = chunk.size();
    AppendRange(segment, segment_offset_, count, chunk);
    CheckValues(segment, segment_offset_, chunk, first);
    segment_offset_ += count;
  }
  return chunk.size() > 0;
}

// The same steps as Next(), without reading.
std::uint64_t SegmentedSource::Skip() {
  if (!SeeksRanges()) return ParticleSource::Skip();
  std::uint64_t skipped = 0;
  while (skipped < chunk_particles_ && segment_index_ < segments_.size()) {
    const std::uint64_t left = segments_[segment_index_].count - segment_offset_;
    if (left == 0) {
      ++segment_index_;
      segment_offset_ = 0;
      continue;
    }
    const std::uint64_t count = std::min<std::uint64_t>(left, chunk_particles_ - skipped);
    segment_offset_ += count;
    skipped += count;
  }
  return skipped;
}

void SegmentedSource::Rewind() {
  segment_index_ = 0;
  segment_offset_ = 0;
  OnRewind();
}

std::string SegmentedSource::DescribeParticle(const Segment& segment, std::uint64_t index) const {
  return "type " + std::to_string(segment.type) + " particle " + std::to_string(index);
}

std::string SegmentedSource::DescribeSmoothing(const Segment& segment) const {
  return "the smoothing lengths of type " + std::to_string(segment.type);
}

void SegmentedSource::CountSegments(std::size_t type_count) {
  header_.count_per_type.assign(type_count, 0);
  header_.total_count = 0;
  for (const Segment& segment : segments_) {
    header_.count_per_type.at(static_cast<std::size_t>(segment.type)) += segment.count;
    header_.total_count += segment.count;
  }
}

void SegmentedSource::SetBoxSize(const std::string& path, const std::string& field, double declared,
                                 const ReadOptions& options) {
  if (options.ignore_box) {
    header_.box_size = 0;
    box_from_.clear();
  } else if (options.box_size_override >= 0) {
    header_.box_size = options.box_size_override;
    box_from_ = "the box size given (--box-size)";
  } else {
    if (!std::isfinite(declared) || declared < 0) {
      std::ostringstream message;
      message << "header field " << field << " is " << declared
              << "; a box size must be finite and >= 0 (0 = not periodic). Give the right one with --box-size, "
                 "or --ignore-box to index the particles' bounding cube";
      throw Error::BadInput(path, message.str());
    }
    header_.box_size = declared;
    box_from_ = "header field " + field;
    return;
  }
  // The header's value is not used; kept for the record when it is a number.
  if (std::isfinite(declared) && declared != header_.box_size) header_.extra["box_size_in_header"] = declared;
}

void SegmentedSource::CheckValues(const Segment& segment, std::uint64_t begin, const ParticleChunk& chunk,
                                  std::size_t first) const {
  const float* smoothing = chunk.has_smoothing() ? chunk.smoothing.data() : nullptr;
  // A periodic box takes [lo, hi] (every position when not periodic).
  const double box = header_.box_size;
  const double lo = box > 0 ? -kPeriodicBoxTolerance * box : -HUGE_VAL;
  const double hi = box > 0 ? (1 + kPeriodicBoxTolerance) * box : HUGE_VAL;
  for (std::size_t i = first; i < chunk.size(); ++i) {
    const double* p = &chunk.position[3 * i];
    const float* v = chunk.has_velocity() ? &chunk.velocity[3 * i] : nullptr;
    const bool position_ok = std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
    const bool velocity_ok = v == nullptr || (std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]));
    const bool mass_ok = std::isfinite(chunk.mass[i]) && chunk.mass[i] > 0;
    // 0 is a length not given; NaN fails the comparison.
    const bool smoothing_ok = smoothing == nullptr || (smoothing[i] >= 0 && std::isfinite(smoothing[i]));
    const bool inside_ok = (p[0] >= lo && p[0] <= hi) && (p[1] >= lo && p[1] <= hi) && (p[2] >= lo && p[2] <= hi);
    if (position_ok && velocity_ok && mass_ok && smoothing_ok && inside_ok) continue;
    std::ostringstream message;
    message << DescribeParticle(segment, begin + (i - first));
    if (chunk.has_id()) message << " (ID " << chunk.id[i] << ")";
    if (!position_ok) {
      message << " has a non-finite coordinate (" << p[0] << ", " << p[1] << ", " << p[2]
              << "); positions must be finite numbers";
    } else if (!velocity_ok) {
      message << " has a non-finite velocity (" << v[0] << ", " << v[1] << ", " << v[2]
              << "); velocities must be finite numbers";
    } else if (!inside_ok) {
      message << " lies at (" << p[0] << ", " << p[1] << ", " << p[2] << "), more than "
              << 100 * kPeriodicBoxTolerance << "% of the box outside the periodic box [0, " << box << ")^3 of "
              << box_from_
              << "; give the right box with --box-size, or --ignore-box to index the particles' bounding cube";
    } else if (!mass_ok) {
      message << " has mass " << chunk.mass[i] << "; masses must be finite and > 0";
    } else {
      message << " has smoothing length " << smoothing[i] << " in " << DescribeSmoothing(segment)
              << "; smoothing lengths must be finite and >= 0";
    }
    throw Error::BadInput(header_.files.at(segment.file), message.str());
  }
}

double RequireFinite(const std::string& path, const std::string& field, double value) {
  if (std::isfinite(value)) return value;
  std::ostringstream message;
  message << "header field " << field << " is " << value << "; it must be a finite number";
  throw Error::BadInput(path, message.str());
}

bool IsTypeSelected(const std::vector<int>& selected, int type) {
  return selected.empty() || std::find(selected.begin(), selected.end(), type) != selected.end();
}

std::vector<std::uint64_t> ReconcileTypeTotals(const std::string& path, const std::vector<std::uint64_t>& low,
                                               const std::vector<std::uint64_t>& high,
                                               const std::vector<std::uint64_t>& file_sums,
                                               nlohmann::json& extra) {
  auto is_zero = [](std::uint64_t v) { return v == 0; };
  if (std::all_of(low.begin(), low.end(), is_zero) && std::all_of(high.begin(), high.end(), is_zero)) {
    if (std::any_of(file_sums.begin(), file_sums.end(), [](std::uint64_t v) { return v != 0; })) {
      extra["totals_from_file_counts"] = true;
    }
    return file_sums;
  }
  std::vector<std::uint64_t> totals(file_sums.size(), 0);
  for (std::size_t type = 0; type < file_sums.size(); ++type) {
    std::uint64_t low_word = type < low.size() ? low[type] : 0;
    std::uint64_t high_word = type < high.size() ? high[type] : 0;
    std::uint64_t combined = low_word + (high_word << 32);
    if (combined == file_sums[type]) {
      totals[type] = combined;
    } else if (low_word == file_sums[type]) {
      totals[type] = low_word;
      extra["ignored_total_high_words"][std::to_string(type)] = high_word;
    } else {
      throw Error::BadInput(path, "counts do not add up: the header total for type " + std::to_string(type) +
                                      " is " + std::to_string(combined) + " (high word " +
                                      std::to_string(high_word) + ") but the files hold " +
                                      std::to_string(file_sums[type]) + " particles of that type");
    }
  }
  return totals;
}

}  // namespace octocosm
