#include "tools/ingest/resident_epoch.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <string>
#include <type_traits>

#include "storage/error.h"
#include "tools/huge_pages.h"

namespace octocosm {
namespace {

// Listed points lie scattered across the columns, so each read of one is a
// cache miss; fetching this many points ahead lets the misses overlap.
constexpr std::size_t kPrefetchDistance = 16;

template <typename Narrow, typename Wide>
bool FitsNarrow(Wide value) {
  if constexpr (std::is_floating_point_v<Narrow>) {
    // The range check first: converting a finite double beyond float's range is undefined.
    return std::fabs(value) <= std::numeric_limits<Narrow>::max() &&
           static_cast<Wide>(static_cast<Narrow>(value)) == value;
  } else {
    return value <= std::numeric_limits<Narrow>::max();
  }
}

// to[width * target[k] + a] = from[width * listed[k] + a], converted to To.
template <typename From, typename To>
void CopyListed(const From* from, std::span<const std::uint32_t> listed, std::span<const std::uint32_t> target,
                std::size_t width, To* to) {
  for (std::size_t k = 0; k < listed.size(); ++k) {
    if (k + kPrefetchDistance < listed.size()) __builtin_prefetch(&from[width * listed[k + kPrefetchDistance]]);
    const std::size_t i = width * std::size_t{listed[k]};
    const std::size_t j = width * std::size_t{target[k]};
    for (std::size_t a = 0; a < width; ++a) to[j + a] = static_cast<To>(from[i + a]);
  }
}

template <typename Narrow, typename Wide>
void CopyListed(const NarrowableColumn<Narrow, Wide>& from, std::span<const std::uint32_t> listed,
                std::span<const std::uint32_t> target, std::size_t width, std::vector<Wide>& to) {
  to.resize(width * listed.size());
  if (from.is_narrow()) {
    CopyListed(from.narrow_values().data(), listed, target, width, to.data());
  } else {
    CopyListed(from.wide_values().data(), listed, target, width, to.data());
  }
}

// Advises `column`'s reserved room onto small pages and lists it for warming.
template <typename T>
void AddFreshRange(std::vector<T>& column, std::vector<PageWarmer::Range>& ranges) {
  if (column.capacity() == 0) return;
  PreferSmallPages(column.data(), column.capacity() * sizeof(T));
  ranges.push_back({column.data(), column.capacity() * sizeof(T)});
}

}  // namespace

template <typename Narrow, typename Wide>
void NarrowableColumn<Narrow, Wide>::Reserve(std::size_t values, std::vector<PageWarmer::Range>& fresh) {
  narrow_.reserve(values);
  AddFreshRange(narrow_, fresh);
}

template <typename Narrow, typename Wide>
void NarrowableColumn<Narrow, Wide>::Append(std::span<const Wide> values) {
  if (!is_wide_) {
    bool fits = true;
    for (const Wide v : values) fits &= FitsNarrow<Narrow>(v);
    if (fits) {
      const std::size_t old = narrow_.size();
      narrow_.resize(old + values.size());
      for (std::size_t i = 0; i < values.size(); ++i) narrow_[old + i] = static_cast<Narrow>(values[i]);
      return;
    }
    wide_.reserve(std::max(narrow_.capacity(), narrow_.size() + values.size()));
    wide_.assign(narrow_.begin(), narrow_.end());
    narrow_ = std::vector<Narrow>();
    is_wide_ = true;
  }
  wide_.insert(wide_.end(), values.begin(), values.end());
}

template class NarrowableColumn<float, double>;
template class NarrowableColumn<std::uint32_t, std::uint64_t>;

std::vector<PageWarmer::Range> ResidentEpoch::Reserve(std::size_t points, const ParticleColumns& columns) {
  columns_ = columns;
  std::vector<PageWarmer::Range> fresh;
  position_.Reserve(3 * points, fresh);
  type_.reserve(points);
  AddFreshRange(type_, fresh);
  if (columns_.id) {
    id_.Reserve(points, fresh);
  }
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (!columns_.vectors[v]) continue;
    vectors_[v].reserve(3 * points);
    AddFreshRange(vectors_[v], fresh);
  }
  return fresh;
}

void ResidentEpoch::Append(const ParticleChunk& batch) {
  const std::size_t n = batch.size();
  bool agree = batch.position.size() == 3 * n && batch.type.size() == n && batch.id.size() == (columns_.id ? n : 0);
  const auto vectors = VectorColumns(batch);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) agree &= vectors[v]->size() == (columns_.vectors[v] ? 3 * n : 0);
  if (!agree) {
    throw Error::InvalidArgument("resident epoch: a batch of " + std::to_string(n) +
                                 " points does not carry the columns the epoch was reserved for");
  }
  if (per_type_mass_) {
    for (std::size_t i = 0; i < n && per_type_mass_; ++i) {
      const std::uint8_t t = batch.type[i];
      if (!type_mass_known_[t]) {
        type_mass_known_[t] = true;
        type_mass_[t] = batch.mass[i];
      } else if (std::bit_cast<std::uint64_t>(type_mass_[t]) != std::bit_cast<std::uint64_t>(batch.mass[i])) {
        WidenMasses();
      }
    }
  }
  if (!per_type_mass_) mass_.insert(mass_.end(), batch.mass.begin(), batch.mass.end());
  type_.insert(type_.end(), batch.type.begin(), batch.type.end());
  position_.Append(batch.position);
  if (columns_.id) id_.Append(batch.id);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    vectors_[v].insert(vectors_[v].end(), vectors[v]->begin(), vectors[v]->end());
  }
}

void ResidentEpoch::WidenMasses() {
  // The points appended so far (type_ does not hold the batch being appended yet).
  mass_.reserve(type_.capacity());
  mass_.resize(type_.size());
  for (std::size_t i = 0; i < type_.size(); ++i) mass_[i] = type_mass_[type_[i]];
  per_type_mass_ = false;
}

std::size_t ResidentEpoch::BytesPerPoint() const {
  std::size_t bytes = 3 * (position_.is_narrow() ? sizeof(float) : sizeof(double)) + sizeof(std::uint8_t);
  if (!per_type_mass_) bytes += sizeof(double);
  if (columns_.id) bytes += id_.is_narrow() ? sizeof(std::uint32_t) : sizeof(std::uint64_t);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) bytes += columns_.vectors[v] ? 3 * sizeof(float) : 0;
  return bytes;
}

std::array<double, 3> ResidentEpoch::Position(std::size_t i) const {
  return {position_[3 * i], position_[3 * i + 1], position_[3 * i + 2]};
}

const void* ResidentEpoch::PositionAddress(std::size_t i) const {
  return position_.is_narrow() ? static_cast<const void*>(&position_.narrow_values()[3 * i])
                               : static_cast<const void*>(&position_.wide_values()[3 * i]);
}

void ResidentEpoch::CopyPoints(std::span<const std::uint32_t> listed, std::span<const std::uint32_t> target,
                               ParticleChunk& to) const {
  const std::size_t n = listed.size();
  CopyListed(position_, listed, target, 3, to.position);
  to.mass.resize(n);
  if (per_type_mass_) {
    for (std::size_t k = 0; k < n; ++k) to.mass[target[k]] = type_mass_[type_[listed[k]]];
  } else {
    CopyListed(mass_.data(), listed, target, 1, to.mass.data());
  }
  to.type.resize(n);
  CopyListed(type_.data(), listed, target, 1, to.type.data());
  if (columns_.id) {
    CopyListed(id_, listed, target, 1, to.id);
  } else {
    to.id.clear();
  }
  const auto out = VectorColumns(to);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (!columns_.vectors[v]) {
      out[v]->clear();
      continue;
    }
    out[v]->resize(3 * n);
    CopyListed(vectors_[v].data(), listed, target, 3, out[v]->data());
  }
}

}  // namespace octocosm
