#include "ingest/particle_file.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <limits>
#include <cstring>
#include <utility>

#include "base/error.h"

namespace octocosm {
namespace {

constexpr char kMagic[8] = {'O', 'C', 'T', 'P', 'T', 'M', 'P', '2'};
constexpr std::size_t kStdioBuffer = std::size_t{1} << 20;

// How a batch stores its fixed columns, chosen per batch by what its values
// allow, so that an out-of-core ingest moves fewer bytes through the disk: a
// GADGET dark-matter snapshot's points take 16 bytes instead of 41.
enum BatchLayout : std::uint8_t {
  kFloatPositions = 1,  // every coordinate is exactly a float
  kOneMass = 2,         // every point weighs the same: the mass once
  kOneType = 4,         // every point has the same type: the type once
  kNarrowIds = 8,       // every ID is below 2^32
};
constexpr std::uint8_t kKnownLayout = kFloatPositions | kOneMass | kOneType | kNarrowIds;

// Values are converted through a scratch buffer a piece at a time, so the
// scratch stays small whatever the batch.
constexpr std::size_t kPieceValues = std::size_t{1} << 16;

template <typename Narrow>
std::vector<Narrow>& Scratch() {
  thread_local std::vector<Narrow> scratch(kPieceValues);
  return scratch;
}

std::uint8_t LayoutOf(const ParticleChunk& chunk, std::size_t begin, std::size_t end, bool with_ids) {
  std::uint8_t layout = kFloatPositions | kOneMass | kOneType | (with_ids ? kNarrowIds : 0);
  for (std::size_t k = 3 * begin; k < 3 * end; ++k) {
    const double x = chunk.position[k];
    // Beyond the float range the conversion itself would be undefined.
    if (!(std::fabs(x) <= std::numeric_limits<float>::max()) || static_cast<double>(static_cast<float>(x)) != x) {
      layout &= ~kFloatPositions;
      break;
    }
  }
  for (std::size_t i = begin + 1; i < end; ++i) {
    // Compared bit for bit: -0.0 and 0.0 are different masses to keep.
    if (std::memcmp(&chunk.mass[i], &chunk.mass[begin], sizeof(double)) != 0) {
      layout &= ~kOneMass;
      break;
    }
  }
  for (std::size_t i = begin + 1; i < end; ++i) {
    if (chunk.type[i] != chunk.type[begin]) {
      layout &= ~kOneType;
      break;
    }
  }
  if (with_ids) {
    for (std::size_t i = begin; i < end; ++i) {
      if (chunk.id[i] > UINT32_MAX) {
        layout &= ~kNarrowIds;
        break;
      }
    }
  }
  return layout;
}

template <typename T>
void ResizeColumn(std::vector<T>& column, std::size_t old_size, std::size_t added, std::size_t width) {
  column.resize((old_size + added) * width);
}

}  // namespace

std::size_t ParticleColumns::BytesPerPoint() const {  // in memory; a file's batch may take fewer
  std::size_t bytes = 33 + (id ? 8 : 0) + (smoothing ? 4 : 0);
  for (const bool present : vectors) bytes += present ? 12 : 0;
  return bytes;
}

ParticleFileWriter::ParticleFileWriter(std::string path, ParticleColumns columns)
    : path_(std::move(path)), columns_(columns) {
  file_ = std::fopen(path_.c_str(), "wb");
  if (file_ == nullptr) throw IoErrorFromErrno(path_, "creating a temporary particle file", errno);
  std::setvbuf(file_, nullptr, _IOFBF, kStdioBuffer);
  Write(kMagic, sizeof kMagic);
  // One flag byte per optional column: the ID, the vectors, the smoothing length.
  static_assert(2 + kVectorColumnCount <= 8);
  std::uint8_t flags[8] = {columns_.id};
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) flags[1 + v] = columns_.vectors[v];
  flags[1 + kVectorColumnCount] = columns_.smoothing;
  Write(flags, sizeof flags);
}

ParticleFileWriter::ParticleFileWriter(ParticleFileWriter&& other) noexcept
    : path_(std::move(other.path_)),
      columns_(other.columns_),
      file_(std::exchange(other.file_, nullptr)),
      point_count_(other.point_count_) {}

ParticleFileWriter& ParticleFileWriter::operator=(ParticleFileWriter&& other) noexcept {
  if (this != &other) {
    if (file_ != nullptr) std::fclose(file_);
    path_ = std::move(other.path_);
    columns_ = other.columns_;
    file_ = std::exchange(other.file_, nullptr);
    point_count_ = other.point_count_;
  }
  return *this;
}

ParticleFileWriter::~ParticleFileWriter() {
  if (file_ != nullptr) std::fclose(file_);
}

void ParticleFileWriter::Write(const void* data, std::size_t size) {
  if (size == 0) return;
  if (std::fwrite(data, 1, size, file_) != size) {
    throw IoErrorFromErrno(path_, "writing a temporary particle file (is the temporary directory full?)", errno);
  }
}

template <typename Narrow, typename Wide>
void ParticleFileWriter::WriteNarrow(const Wide* values, std::size_t count) {
  std::vector<Narrow>& scratch = Scratch<Narrow>();
  for (std::size_t done = 0; done < count; done += kPieceValues) {
    const std::size_t piece = std::min(kPieceValues, count - done);
    for (std::size_t k = 0; k < piece; ++k) scratch[k] = static_cast<Narrow>(values[done + k]);
    Write(scratch.data(), piece * sizeof(Narrow));
  }
}

void ParticleFileWriter::Append(const ParticleChunk& chunk, std::size_t begin, std::size_t end) {
  if (file_ == nullptr) throw Error::InvalidArgument(path_ + ": append after close");
  if (end <= begin) return;
  const std::uint64_t n = end - begin;
  const std::uint8_t layout = LayoutOf(chunk, begin, end, columns_.id);
  Write(&n, sizeof n);
  Write(&layout, sizeof layout);
  if (layout & kFloatPositions) {
    WriteNarrow<float>(chunk.position.data() + 3 * begin, 3 * n);
  } else {
    Write(chunk.position.data() + 3 * begin, 3 * n * sizeof(double));
  }
  Write(chunk.mass.data() + begin, ((layout & kOneMass) ? 1 : n) * sizeof(double));
  Write(chunk.type.data() + begin, (layout & kOneType) ? 1 : n);
  if (columns_.id) {
    if (layout & kNarrowIds) {
      WriteNarrow<std::uint32_t>(chunk.id.data() + begin, n);
    } else {
      Write(chunk.id.data() + begin, n * sizeof(std::uint64_t));
    }
  }
  if (columns_.smoothing) Write(chunk.smoothing.data() + begin, n * sizeof(float));
  const auto vectors = VectorColumns(chunk);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (columns_.vectors[v]) Write(vectors[v]->data() + 3 * begin, 3 * n * sizeof(float));
  }
  point_count_ += n;
}

void ParticleFileWriter::Close() {
  if (file_ == nullptr) return;
  std::FILE* file = std::exchange(file_, nullptr);
  const bool flushed = std::fflush(file) == 0;
  const int flush_errno = errno;
  const bool closed = std::fclose(file) == 0;
  if (!flushed || !closed) {
    throw IoErrorFromErrno(path_, "closing a temporary particle file", flushed ? errno : flush_errno);
  }
}

ParticleFileReader::ParticleFileReader(std::string path) : path_(std::move(path)) {
  file_ = std::fopen(path_.c_str(), "rb");
  if (file_ == nullptr) throw IoErrorFromErrno(path_, "opening a temporary particle file", errno);
  std::setvbuf(file_, nullptr, _IOFBF, kStdioBuffer);
  char magic[8];
  std::uint8_t flags[8];
  Read(magic, sizeof magic, "header");
  Read(flags, sizeof flags, "header");
  if (std::memcmp(magic, kMagic, sizeof magic) != 0) {
    throw Error::Corruption(path_, "not an octocosm temporary particle file (wrong magic)");
  }
  columns_.id = flags[0] != 0;
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) columns_.vectors[v] = flags[1 + v] != 0;
  columns_.smoothing = flags[1 + kVectorColumnCount] != 0;
}

ParticleFileReader::ParticleFileReader(ParticleFileReader&& other) noexcept
    : path_(std::move(other.path_)), columns_(other.columns_), file_(std::exchange(other.file_, nullptr)) {}

ParticleFileReader& ParticleFileReader::operator=(ParticleFileReader&& other) noexcept {
  if (this != &other) {
    if (file_ != nullptr) std::fclose(file_);
    path_ = std::move(other.path_);
    columns_ = other.columns_;
    file_ = std::exchange(other.file_, nullptr);
  }
  return *this;
}

ParticleFileReader::~ParticleFileReader() {
  if (file_ != nullptr) std::fclose(file_);
}

void ParticleFileReader::Read(void* data, std::size_t size, const char* what) {
  if (size == 0) return;
  if (std::fread(data, 1, size, file_) != size) {
    if (std::ferror(file_)) throw IoErrorFromErrno(path_, std::string("reading ") + what, errno);
    throw Error::Corruption(path_, std::string("temporary particle file ends inside a batch ") + what);
  }
}

template <typename Narrow, typename Wide>
void ParticleFileReader::ReadNarrow(Wide* values, std::size_t count, const char* what) {
  std::vector<Narrow>& scratch = Scratch<Narrow>();
  for (std::size_t done = 0; done < count; done += kPieceValues) {
    const std::size_t piece = std::min(kPieceValues, count - done);
    Read(scratch.data(), piece * sizeof(Narrow), what);
    for (std::size_t k = 0; k < piece; ++k) values[done + k] = static_cast<Wide>(scratch[k]);
  }
}

bool ParticleFileReader::ReadBatch(ParticleChunk& chunk, bool append) {
  std::uint64_t n = 0;
  const std::size_t got = std::fread(&n, 1, sizeof n, file_);
  if (got == 0 && std::feof(file_)) return false;
  if (got != sizeof n) Read(&n, sizeof n, "count");  // reports the short read
  if (n == 0 || n > (std::uint64_t{1} << 40)) throw Error::Corruption(path_, "impossible batch size " + std::to_string(n));
  std::uint8_t layout = 0;
  Read(&layout, sizeof layout, "layout");
  if ((layout & ~kKnownLayout) != 0 || ((layout & kNarrowIds) && !columns_.id)) {
    throw Error::Corruption(path_, "impossible batch layout " + std::to_string(layout));
  }
  const std::size_t old = append ? chunk.size() : 0;
  if (!append) chunk.clear();
  ResizeColumn(chunk.position, old, n, 3);
  ResizeColumn(chunk.mass, old, n, 1);
  ResizeColumn(chunk.type, old, n, 1);
  if (layout & kFloatPositions) {
    ReadNarrow<float>(chunk.position.data() + 3 * old, 3 * n, "positions");
  } else {
    Read(chunk.position.data() + 3 * old, 3 * n * sizeof(double), "positions");
  }
  if (layout & kOneMass) {
    Read(chunk.mass.data() + old, sizeof(double), "masses");
    std::fill(chunk.mass.begin() + static_cast<std::ptrdiff_t>(old + 1), chunk.mass.end(), chunk.mass[old]);
  } else {
    Read(chunk.mass.data() + old, n * sizeof(double), "masses");
  }
  if (layout & kOneType) {
    Read(chunk.type.data() + old, 1, "types");
    std::fill(chunk.type.begin() + static_cast<std::ptrdiff_t>(old + 1), chunk.type.end(), chunk.type[old]);
  } else {
    Read(chunk.type.data() + old, n, "types");
  }
  if (columns_.id) {
    ResizeColumn(chunk.id, old, n, 1);
    if (layout & kNarrowIds) {
      ReadNarrow<std::uint32_t>(chunk.id.data() + old, n, "IDs");
    } else {
      Read(chunk.id.data() + old, n * sizeof(std::uint64_t), "IDs");
    }
  }
  if (columns_.smoothing) {
    ResizeColumn(chunk.smoothing, old, n, 1);
    Read(chunk.smoothing.data() + old, n * sizeof(float), "smoothing lengths");
  }
  const auto vectors = VectorColumns(chunk);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (!columns_.vectors[v]) continue;
    ResizeColumn(*vectors[v], old, n, 3);
    Read(vectors[v]->data() + 3 * old, 3 * n * sizeof(float), "vector columns");
  }
  return true;
}

bool ParticleFileReader::Next(ParticleChunk& chunk) { return ReadBatch(chunk, false); }

void ParticleFileReader::ReadAll(ParticleChunk& chunk) {
  while (ReadBatch(chunk, true)) {
  }
}

}  // namespace octocosm
