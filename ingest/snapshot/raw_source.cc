#include "ingest/snapshot/raw_source.h"

#include <bit>
#include <cstring>

#include "base/error.h"
#include "ingest/snapshot/binary_file.h"
#include "ingest/snapshot/segmented_source.h"

namespace octocosm {
namespace {

using Field = RawColumn::Field;
using Scalar = RawColumn::Scalar;

template <typename T>
T Load(const std::uint8_t* bytes, bool swap) {
  std::uint8_t copy[sizeof(T)];
  std::memcpy(copy, bytes, sizeof(T));
  if (swap) SwapByteOrder(copy, 1, sizeof(T));
  T value;
  std::memcpy(&value, copy, sizeof(T));
  return value;
}

double LoadReal(const std::uint8_t* bytes, Scalar scalar, bool swap) {
  switch (scalar) {
    case Scalar::kF32: return Load<float>(bytes, swap);
    case Scalar::kF64: return Load<double>(bytes, swap);
    case Scalar::kU32: return Load<std::uint32_t>(bytes, swap);
    case Scalar::kU64: return static_cast<double>(Load<std::uint64_t>(bytes, swap));
    case Scalar::kI32: return Load<std::int32_t>(bytes, swap);
    case Scalar::kI64: return static_cast<double>(Load<std::int64_t>(bytes, swap));
  }
  return 0;
}

class RawSource final : public SegmentedSource {
 public:
  RawSource(const std::string& path, const ReadOptions& options)
      : SegmentedSource(options.chunk_particles), layout_(options.raw), file_(path) {
    if (layout_.empty()) {
      throw Error::InvalidArgument("raw input " + path + " needs a record layout (e.g. \"xyz:f32\")");
    }
    if (file_.size() == 0) throw Error::BadInput(path, "empty input: the file holds no records");
    if (file_.size() % layout_.record_bytes != 0) {
      throw Error::BadInput(path, "file size " + std::to_string(file_.size()) + " is not a whole number of " +
                                      std::to_string(layout_.record_bytes) + "-byte records (layout \"" +
                                      layout_.text + "\"); truncated file or wrong layout?");
    }
    swap_ = layout_.big_endian != (std::endian::native == std::endian::big);
    header_.format = "raw";
    header_.files = {path};
    header_.has_velocity = options.read_velocity && layout_.has(Field::kVx);
    header_.has_id = options.read_id && layout_.has(Field::kId);
    SetBoxSize(path, "BoxSize", 0, options);  // no header: periodic only when given
    header_.extra["raw_layout"] = layout_.text;
    header_.extra["record_bytes"] = layout_.record_bytes;
    if (IsTypeSelected(options.types, 0)) segments_.push_back(Segment{0, 0, file_.size() / layout_.record_bytes});
    CountSegments(1);
  }

 protected:
  void AppendRange(const Segment&, std::uint64_t begin, std::size_t count, ParticleChunk& chunk) override {
    buffer_.resize(count * layout_.record_bytes);
    file_.ReadAt(begin * layout_.record_bytes, buffer_.data(), buffer_.size(), "records");
    const std::size_t old = chunk.size();
    chunk.position.resize(3 * (old + count));
    if (FillsVelocity()) chunk.velocity.resize(3 * (old + count));
    if (FillsId()) chunk.id.resize(old + count);
    chunk.mass.resize(old + count, 1.0);
    chunk.type.resize(old + count, 0);
    for (std::size_t i = 0; i < count; ++i) {
      const std::uint8_t* record = buffer_.data() + i * layout_.record_bytes;
      const std::size_t p = old + i;
      for (const RawColumn& column : layout_.columns) {
        const std::uint8_t* bytes = record + column.offset;
        switch (column.field) {
          case Field::kX: chunk.position[3 * p] = LoadReal(bytes, column.scalar, swap_); break;
          case Field::kY: chunk.position[3 * p + 1] = LoadReal(bytes, column.scalar, swap_); break;
          case Field::kZ: chunk.position[3 * p + 2] = LoadReal(bytes, column.scalar, swap_); break;
          case Field::kVx:
          case Field::kVy:
          case Field::kVz:
            if (FillsVelocity()) {
              auto component = static_cast<std::size_t>(column.field) - static_cast<std::size_t>(Field::kVx);
              chunk.velocity[3 * p + component] = static_cast<float>(LoadReal(bytes, column.scalar, swap_));
            }
            break;
          case Field::kMass: chunk.mass[p] = LoadReal(bytes, column.scalar, swap_); break;
          case Field::kId:
            if (FillsId()) chunk.id[p] = LoadId(bytes, column.scalar, begin + i);
            break;
          case Field::kSkip: break;
        }
      }
    }
  }

  std::string DescribeParticle(const Segment&, std::uint64_t index) const override {
    return "record " + std::to_string(index);
  }

 private:
  std::uint64_t LoadId(const std::uint8_t* bytes, Scalar scalar, std::uint64_t record) const {
    std::int64_t value = 0;
    switch (scalar) {
      case Scalar::kU32: return Load<std::uint32_t>(bytes, swap_);
      case Scalar::kU64: return Load<std::uint64_t>(bytes, swap_);
      case Scalar::kI32: value = Load<std::int32_t>(bytes, swap_); break;
      case Scalar::kI64: value = Load<std::int64_t>(bytes, swap_); break;
      case Scalar::kF32:
      case Scalar::kF64: break;  // rejected by RawLayout::Parse
    }
    if (value < 0) {
      throw Error::BadInput(file_.path(), "record " + std::to_string(record) + " has a negative id (" +
                                              std::to_string(value) + ")");
    }
    return static_cast<std::uint64_t>(value);
  }

  RawLayout layout_;
  BinaryFile file_;
  bool swap_ = false;
  std::vector<std::uint8_t> buffer_;
};

}  // namespace

std::unique_ptr<ParticleSource> OpenRawSnapshot(const std::string& file, const ReadOptions& options) {
  return std::make_unique<RawSource>(file, options);
}

}  // namespace octocosm
