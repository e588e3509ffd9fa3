#include "ingest/clipped_source.h"

#include <algorithm>
#include <bit>
#include <span>

#include "base/error.h"

namespace octocosm {
namespace {

template <typename T>
void KeepValues(const std::vector<T>& in, const std::vector<std::uint64_t>& kept, std::size_t width, std::vector<T>& out) {
  out.clear();
  if (in.empty()) return;
  out.reserve(kept.size() * width);
  for (std::size_t i : kept) out.insert(out.end(), in.begin() + static_cast<std::ptrdiff_t>(i * width),
                                        in.begin() + static_cast<std::ptrdiff_t>((i + 1) * width));
}

}  // namespace

ClippedSource::ClippedSource(std::unique_ptr<ParticleSource> inner, const PositionBox& box, const std::string& reason,
                             RankGroup* group)
    : inner_(std::move(inner)), box_(box), header_(inner_->header()) {
  const std::uint64_t read_count = header_.total_count;
  Count(group);
  counting_ = false;
  inner_->Rewind();
  if (header_.total_count == 0) {
    throw Error::BadInput(header_.files.front(), "none of its " + std::to_string(read_count) +
                                                     " particles lies inside the box " + box_.ToString() + " (" +
                                                     reason + "): nothing would be left to ingest");
  }
  nlohmann::json& dropped = header_.extra["dropped"];
  if (!dropped.is_array()) dropped = nlohmann::json::array();
  dropped.push_back({{"reason", reason},
                     {"box", {box_.lo, box_.hi}},
                     {"read", read_count},
                     {"dropped", dropped_},
                     {"kept", header_.total_count}});
}

void ClippedSource::Count(RankGroup* group) {
  const std::uint64_t ranks = group != nullptr ? static_cast<std::uint64_t>(group->size()) : 1;
  const std::uint64_t rank = group != nullptr ? static_cast<std::uint64_t>(group->rank()) : 0;
  std::fill(header_.count_per_type.begin(), header_.count_per_type.end(), 0);
  header_.total_count = 0;
  ParticleChunk kept;
  std::vector<std::uint64_t> indices;
  ReadShare(*inner_, ranks, rank, read_, [&](const ParticleChunk& batch, std::uint64_t first_index) {
    Keep(batch, kept);
    indices.resize(kept_.size());
    for (std::size_t i = 0; i < kept_.size(); ++i) indices[i] = first_index + kept_[i];
    survey_.Add(kept, indices);
    for (std::uint8_t type : kept.type) {
      if (type < header_.count_per_type.size()) ++header_.count_per_type[type];
    }
    header_.total_count += kept.size();
  });
  if (group == nullptr) return;
  std::vector<std::uint64_t> counts = header_.count_per_type;
  counts.push_back(header_.total_count);
  counts.push_back(dropped_);
  group->Sum(counts);
  dropped_ = counts.back();
  header_.total_count = counts[counts.size() - 2];
  std::copy(counts.begin(), counts.begin() + static_cast<std::ptrdiff_t>(header_.count_per_type.size()),
            header_.count_per_type.begin());
  // Distances are >= 0, whose bit patterns order as the values do.
  std::uint64_t farthest = std::bit_cast<std::uint64_t>(farthest_dropped_);
  group->Max(std::span<std::uint64_t>(&farthest, 1));
  farthest_dropped_ = std::bit_cast<double>(farthest);
  MergeAcrossRanks(survey_, *group);
}

bool ClippedSource::Next(ParticleChunk& chunk) {
  while (inner_->Next(read_)) {
    Keep(read_, chunk);
    if (chunk.size() > 0) return true;
  }
  chunk.clear();
  return false;
}

void ClippedSource::Keep(const ParticleChunk& in, ParticleChunk& out) {
  std::vector<std::uint64_t>& kept = kept_;
  kept.clear();
  std::uint64_t dropped = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    const double* p = &in.position[3 * i];
    if (box_.Holds(p)) {
      kept.push_back(i);
    } else {
      ++dropped;
      farthest_dropped_ = std::max(farthest_dropped_, box_.DistanceOutside(p));
    }
  }
  // Counted on the first pass only: later passes hand out the same particles.
  if (counting_) dropped_ += dropped;
  KeepValues(in.position, kept, 3, out.position);
  KeepValues(in.mass, kept, 1, out.mass);
  KeepValues(in.id, kept, 1, out.id);
  KeepValues(in.type, kept, 1, out.type);
  KeepValues(in.smoothing, kept, 1, out.smoothing);
  const auto in_vectors = VectorColumns(in);
  const auto out_vectors = VectorColumns(out);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) KeepValues(*in_vectors[v], kept, 3, *out_vectors[v]);
}

}  // namespace octocosm
