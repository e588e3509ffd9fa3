#include "ingest/resident_epoch.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <string>
#include <type_traits>

#include "base/error.h"
#include "base/huge_pages.h"
#include "base/parallel_for.h"

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

// A point's run is found from a table of the run that holds the first point
// of each block of 2^kRunBlockBits points, stepping forward from there.
constexpr int kRunBlockBits = 16;

// Value `index` of an array of T at `base`, wherever it is aligned.
template <typename T>
T LoadAt(const void* base, std::size_t index) {
  T value;
  std::memcpy(&value, static_cast<const std::byte*>(base) + index * sizeof(T), sizeof(T));
  return value;
}

// to[width * target[k] + a] = from[width * (listed[k] - first) + a], converted to To.
template <typename From, typename To>
void CopyListed(const void* from, std::size_t first, std::span<const std::uint32_t> listed,
                std::span<const std::uint32_t> target, std::size_t width, To* to) {
  const auto* bytes = static_cast<const std::byte*>(from);
  for (std::size_t k = 0; k < listed.size(); ++k) {
    if (k + kPrefetchDistance < listed.size()) {
      __builtin_prefetch(bytes + sizeof(From) * width * (listed[k + kPrefetchDistance] - first));
    }
    const std::size_t i = width * (std::size_t{listed[k]} - first);
    const std::size_t j = width * std::size_t{target[k]};
    for (std::size_t a = 0; a < width; ++a) to[j + a] = static_cast<To>(LoadAt<From>(from, i + a));
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

// Bytes [offset, offset + bytes) of a file, mapped read-only.
class ResidentEpoch::Mapping {
 public:
  // Null where the file cannot be opened or mapped or is too short.
  static std::unique_ptr<Mapping> Map(const std::string& path, std::uint64_t offset, std::uint64_t bytes) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return nullptr;
    struct stat status{};
    const std::uint64_t page = static_cast<std::uint64_t>(::sysconf(_SC_PAGESIZE));
    const std::uint64_t start = offset / page * page;
    void* data = MAP_FAILED;
    if (::fstat(fd, &status) == 0 && bytes > 0 && offset + bytes <= static_cast<std::uint64_t>(status.st_size)) {
      data = ::mmap(nullptr, offset + bytes - start, PROT_READ, MAP_PRIVATE, fd, static_cast<off_t>(start));
    }
    // Pages not cached are read ahead while the first are looked at.
    if (data != MAP_FAILED) ::madvise(data, offset + bytes - start, MADV_WILLNEED);
    ::close(fd);  // the mapping keeps the file
    if (data == MAP_FAILED) return nullptr;
    return std::unique_ptr<Mapping>(new Mapping(data, offset + bytes - start, offset - start));
  }
  ~Mapping() { ::munmap(data_, length_); }
  Mapping(const Mapping&) = delete;
  Mapping& operator=(const Mapping&) = delete;

  // The byte `from_start` bytes past the offset asked for.
  const std::byte* at(std::uint64_t from_start) const { return static_cast<const std::byte*>(data_) + lead_ + from_start; }
  std::size_t length() const { return length_; }

 private:
  Mapping(void* data, std::size_t length, std::size_t lead) : data_(data), length_(length), lead_(lead) {}
  void* data_;
  std::size_t length_;
  std::size_t lead_;  // bytes mapped before the requested offset, to start on a page
};

ResidentEpoch::ResidentEpoch() = default;
ResidentEpoch::~ResidentEpoch() = default;
ResidentEpoch::ResidentEpoch(ResidentEpoch&&) noexcept = default;
ResidentEpoch& ResidentEpoch::operator=(ResidentEpoch&&) noexcept = default;

void ResidentEpoch::Read(const PointPass& pass, std::size_t expected_points, const ParticleColumns& columns) {
  *this = ResidentEpoch();
  {
    PageWarmer warmer(Reserve(expected_points, columns));
    pass([&](const ParticleChunk& batch) { Append(batch); });
  }
  if (size_ > UINT32_MAX) {
    throw Error::InvalidArgument("resident epoch: " + std::to_string(size_) +
                                 " points are more than one resident epoch holds (2^32 - 1)");
  }
}

std::vector<PageWarmer::Range> ResidentEpoch::Reserve(std::size_t points, const ParticleColumns& columns) {
  columns_ = columns;
  std::vector<PageWarmer::Range> fresh;
  position_.Reserve(3 * points, fresh);
  type_.reserve(points);
  AddFreshRange(type_, fresh);
  if (columns_.id) {
    id_.Reserve(points, fresh);
  }
  if (columns_.smoothing) {
    smoothing_.reserve(points);
    AddFreshRange(smoothing_, fresh);
  }
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (!columns_.vectors[v]) continue;
    vectors_[v].reserve(3 * points);
    AddFreshRange(vectors_[v], fresh);
  }
  DescribeOwnColumns();
  return fresh;
}

void ResidentEpoch::Append(const ParticleChunk& batch) {
  if (mapped()) throw Error::InvalidArgument("resident epoch: a mapped epoch takes no appended points");
  const std::size_t n = batch.size();
  bool agree = batch.position.size() == 3 * n && batch.type.size() == n && batch.id.size() == (columns_.id ? n : 0) &&
               batch.smoothing.size() == (columns_.smoothing ? n : 0);
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
  smoothing_.insert(smoothing_.end(), batch.smoothing.begin(), batch.smoothing.end());
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    vectors_[v].insert(vectors_[v].end(), vectors[v]->begin(), vectors[v]->end());
  }
  size_ = type_.size();
  DescribeOwnColumns();
}

void ResidentEpoch::WidenMasses() {
  // The points appended so far (type_ does not hold the batch being appended yet).
  mass_.reserve(type_.capacity());
  mass_.resize(type_.size());
  for (std::size_t i = 0; i < type_.size(); ++i) mass_[i] = type_mass_[type_[i]];
  per_type_mass_ = false;
}

void ResidentEpoch::DescribeOwnColumns() {
  Run run;
  run.count = size_;
  run.positions_wide = !position_.is_narrow();
  run.position = run.positions_wide ? static_cast<const void*>(position_.wide_values().data())
                                    : static_cast<const void*>(position_.narrow_values().data());
  run.type = type_.data();
  run.mass = per_type_mass_ ? nullptr : mass_.data();
  if (columns_.id) {
    run.id_bytes = id_.is_narrow() ? sizeof(std::uint32_t) : sizeof(std::uint64_t);
    run.id = id_.is_narrow() ? static_cast<const void*>(id_.narrow_values().data())
                             : static_cast<const void*>(id_.wide_values().data());
  }
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) run.vectors[v] = vectors_[v].data();
  run.smoothing = smoothing_.data();
  runs_.assign(1, run);
  run_of_block_.clear();
}

bool ResidentEpoch::Map(std::span<const MappableSegment> segments, std::span<const std::string> files,
                        const ParticleColumns& columns) {
  *this = ResidentEpoch();
  const auto refuse = [this] {
    *this = ResidentEpoch();
    return false;
  };
  ParticleColumns allowed;
  allowed.id = columns.id;
  allowed.vector(VectorColumn::kVelocity) = columns.vector(VectorColumn::kVelocity);
  if (allowed.vectors != columns.vectors || columns.smoothing || segments.empty()) return refuse();
  const bool velocity = columns.vector(VectorColumn::kVelocity);

  // Each file's range: from its first needed byte to its last.
  std::map<std::size_t, std::pair<std::uint64_t, std::uint64_t>> ranges;  // file -> [lo, hi)
  std::uint64_t points = 0;
  for (const MappableSegment& s : segments) {
    if (s.file >= files.size() || s.type < 0 || s.type > 255 || s.count == 0) return refuse();
    if (columns.id && s.id_bytes != 4 && s.id_bytes != 8) return refuse();
    const auto t = static_cast<std::size_t>(s.type);
    if (type_mass_known_[t] && std::bit_cast<std::uint64_t>(type_mass_[t]) != std::bit_cast<std::uint64_t>(s.mass)) {
      return refuse();
    }
    type_mass_known_[t] = true;
    type_mass_[t] = s.mass;
    auto [it, fresh] = ranges.try_emplace(s.file, UINT64_MAX, 0);
    auto cover = [&range = it->second](std::uint64_t offset, std::uint64_t bytes) {
      range.first = std::min(range.first, offset);
      range.second = std::max(range.second, offset + bytes);
    };
    cover(s.position_offset, 12 * s.count);
    if (velocity) cover(s.velocity_offset, 12 * s.count);
    if (columns.id) cover(s.id_offset, s.id_bytes * s.count);
    points += s.count;
  }
  if (points > UINT32_MAX) return refuse();

  std::map<std::size_t, const Mapping*> mapping_of;
  for (const auto& [file, range] : ranges) {
    std::unique_ptr<Mapping> mapping = Mapping::Map(files[file], range.first, range.second - range.first);
    if (!mapping) return refuse();
    mapping_of[file] = mapping.get();
    mappings_.push_back(std::move(mapping));
  }
  columns_ = columns;
  for (const MappableSegment& s : segments) {
    const Mapping& mapping = *mapping_of.at(s.file);
    const std::uint64_t lo = ranges.at(s.file).first;
    Run run;
    run.begin = size_;
    run.count = s.count;
    run.position = mapping.at(s.position_offset - lo);
    run.run_type = static_cast<std::uint8_t>(s.type);
    if (columns.id) {
      run.id = mapping.at(s.id_offset - lo);
      run.id_bytes = s.id_bytes;
    }
    if (velocity) run.vectors[static_cast<std::size_t>(VectorColumn::kVelocity)] = mapping.at(s.velocity_offset - lo);
    runs_.push_back(run);
    size_ += s.count;
  }
  run_of_block_.resize((size_ >> kRunBlockBits) + 1);
  std::size_t r = 0;
  for (std::size_t block = 0; block < run_of_block_.size(); ++block) {
    while (r + 1 < runs_.size() && runs_[r].begin + runs_[r].count <= block << kRunBlockBits) ++r;
    run_of_block_[block] = static_cast<std::uint32_t>(r);
  }
  return true;
}

bool ResidentEpoch::ValuesAsRead(const Cube& cube, int threads, const std::function<void(std::size_t)>& progress) const {
  const std::size_t velocity = static_cast<std::size_t>(VectorColumn::kVelocity);
  std::atomic<bool> usable = true;
  for (const Run& run : runs_) {
    ParallelForDynamic(run.count, threads, std::size_t{1} << 16, [&](std::size_t begin, std::size_t end) {
      bool ok = true;
      for (std::size_t i = begin; i < end; ++i) {
        for (std::size_t a = 0; a < 3; ++a) {
          const double x = run.positions_wide ? LoadAt<double>(run.position, 3 * i + a)
                                              : LoadAt<float>(run.position, 3 * i + a);
          const double t = x - cube.origin[a];
          // As ingest's InsideBox, and a non-finite x fails it too.
          ok &= cube.periodic ? (t >= 0 && t < cube.size) : std::isfinite(x);
        }
        if (run.vectors[velocity] != nullptr) {
          for (std::size_t a = 0; a < 3; ++a) ok &= std::isfinite(LoadAt<float>(run.vectors[velocity], 3 * i + a));
        }
      }
      if (!ok) usable = false;
    });
    if (!usable) return false;
    progress(run.count);
  }
  return true;
}

void ResidentEpoch::VisitIds(const std::function<void(std::span<const std::uint64_t>)>& visit) const {
  if (!columns_.id) throw Error::InvalidArgument("resident epoch: VisitIds needs the ID column");
  constexpr std::size_t kBatch = std::size_t{1} << 16;
  std::vector<std::uint64_t> batch;
  for (const Run& run : runs_) {
    for (std::size_t begin = 0; begin < run.count; begin += kBatch) {
      const std::size_t n = std::min(kBatch, run.count - begin);
      batch.resize(n);
      for (std::size_t k = 0; k < n; ++k) {
        batch[k] = run.id_bytes == 4 ? LoadAt<std::uint32_t>(run.id, begin + k) : LoadAt<std::uint64_t>(run.id, begin + k);
      }
      visit(batch);
    }
  }
}

std::size_t ResidentEpoch::BytesPerPoint() const {
  if (mapped()) {
    std::size_t bytes = 0;
    for (const auto& mapping : mappings_) bytes += mapping->length();
    return size_ == 0 ? 0 : bytes / size_;
  }
  std::size_t bytes = 3 * (position_.is_narrow() ? sizeof(float) : sizeof(double)) + sizeof(std::uint8_t);
  if (!per_type_mass_) bytes += sizeof(double);
  if (columns_.id) bytes += id_.is_narrow() ? sizeof(std::uint32_t) : sizeof(std::uint64_t);
  if (columns_.smoothing) bytes += sizeof(float);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) bytes += columns_.vectors[v] ? 3 * sizeof(float) : 0;
  return bytes;
}

bool ResidentEpoch::positions_narrow() const {
  return std::none_of(runs_.begin(), runs_.end(), [](const Run& run) { return run.positions_wide; });
}

bool ResidentEpoch::ids_narrow() const {
  return std::all_of(runs_.begin(), runs_.end(), [](const Run& run) { return run.id_bytes != 8; });
}

const ResidentEpoch::Run& ResidentEpoch::RunOf(std::size_t i) const {
  if (runs_.size() == 1) return runs_.front();
  std::size_t r = run_of_block_[i >> kRunBlockBits];
  while (i - runs_[r].begin >= runs_[r].count) ++r;
  return runs_[r];
}

std::array<double, 3> ResidentEpoch::Position(std::size_t i) const {
  const Run& run = RunOf(i);
  std::array<double, 3> position;
  LoadPosition(run, i - run.begin, position.data());
  return position;
}

const void* ResidentEpoch::PositionAddress(std::size_t i) const {
  const Run& run = RunOf(i);
  const std::size_t bytes = run.positions_wide ? sizeof(double) : sizeof(float);
  return static_cast<const std::byte*>(run.position) + 3 * bytes * (i - run.begin);
}

void ResidentEpoch::CopyPoints(std::span<const std::uint32_t> listed, std::span<const std::uint32_t> target,
                               ParticleChunk& to) const {
  const std::size_t n = listed.size();
  to.position.resize(3 * n);
  to.mass.resize(n);
  to.type.resize(n);
  to.id.resize(columns_.id ? n : 0);
  to.smoothing.resize(columns_.smoothing ? n : 0);
  const auto out = VectorColumns(to);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) out[v]->resize(columns_.vectors[v] ? 3 * n : 0);

  // Stretch by stretch of listed points that lie in one run.
  for (std::size_t k0 = 0; k0 < n;) {
    const Run& run = RunOf(listed[k0]);
    std::size_t k1 = k0 + 1;
    while (k1 < n && listed[k1] - run.begin < run.count) ++k1;
    const std::span<const std::uint32_t> from = listed.subspan(k0, k1 - k0);
    const std::span<const std::uint32_t> into = target.subspan(k0, k1 - k0);
    k0 = k1;
    if (run.positions_wide) {
      CopyListed<double>(run.position, run.begin, from, into, 3, to.position.data());
    } else {
      CopyListed<float>(run.position, run.begin, from, into, 3, to.position.data());
    }
    if (run.type != nullptr) {
      CopyListed<std::uint8_t>(run.type, run.begin, from, into, 1, to.type.data());
    } else {
      for (const std::uint32_t t : into) to.type[t] = run.run_type;
    }
    if (run.mass != nullptr) {
      CopyListed<double>(run.mass, run.begin, from, into, 1, to.mass.data());
    } else if (run.type != nullptr) {
      for (std::size_t k = 0; k < from.size(); ++k) to.mass[into[k]] = type_mass_[run.type[from[k] - run.begin]];
    } else {
      for (const std::uint32_t t : into) to.mass[t] = type_mass_[run.run_type];
    }
    if (columns_.id) {
      if (run.id_bytes == 4) {
        CopyListed<std::uint32_t>(run.id, run.begin, from, into, 1, to.id.data());
      } else {
        CopyListed<std::uint64_t>(run.id, run.begin, from, into, 1, to.id.data());
      }
    }
    if (columns_.smoothing) CopyListed<float>(run.smoothing, run.begin, from, into, 1, to.smoothing.data());
    for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
      if (columns_.vectors[v]) CopyListed<float>(run.vectors[v], run.begin, from, into, 3, out[v]->data());
    }
  }
}

}  // namespace octocosm
