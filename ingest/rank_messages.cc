#include "ingest/rank_messages.h"

#include <cstring>
#include <string>
#include <vector>

#include "base/error.h"

namespace octocosm {

namespace {

void AppendRaw(const void* data, std::size_t size, Bytes& out) {
  if (size == 0) return;
  const std::size_t start = out.size();
  out.resize(start + size);
  std::memcpy(out.data() + start, data, size);
}

template <typename T>
void AppendValue(T value, Bytes& out) {
  AppendRaw(&value, sizeof value, out);
}

// The values `indices` of a column of `width` values a point.
template <typename T>
void AppendPicked(const std::vector<T>& column, std::size_t width, std::span<const std::uint32_t> indices, Bytes& out) {
  const std::size_t start = out.size();
  const std::size_t point_bytes = width * sizeof(T);
  out.resize(start + indices.size() * point_bytes);
  // Byte by byte: a segment's columns need not lie at their type's alignment.
  std::uint8_t* to = out.data() + start;
  for (std::uint32_t i : indices) {
    std::memcpy(to, column.data() + std::size_t{i} * width, point_bytes);
    to += point_bytes;
  }
}

class Cursor {
 public:
  Cursor(std::span<const std::uint8_t> message, std::size_t offset, const char* what)
      : message_(message), offset_(offset), what_(what) {}
  void Read(void* data, std::size_t size) {
    if (size > message_.size() - offset_) CutShort();
    if (size > 0) std::memcpy(data, message_.data() + offset_, size);
    offset_ += size;
  }
  template <typename T>
  T Value() {
    T value{};
    Read(&value, sizeof value);
    return value;
  }
  template <typename T>
  void Column(std::vector<T>& column, std::size_t count) {
    if (count > (message_.size() - offset_) / sizeof(T)) CutShort();
    column.resize(count);
    Read(column.data(), count * sizeof(T));
  }
  std::size_t offset() const { return offset_; }
  bool done() const { return offset_ == message_.size(); }

 private:
  [[noreturn]] void CutShort() const {
    throw Error::Corruption(what_, "a message between ranks is cut short at byte " + std::to_string(offset_) + " of " +
                                       std::to_string(message_.size()));
  }

  std::span<const std::uint8_t> message_;
  std::size_t offset_;
  const char* what_;
};

template <typename T>
void AppendColumn(const std::vector<T>& column, Bytes& out) {
  AppendValue<std::uint64_t>(column.size(), out);
  AppendRaw(column.data(), column.size() * sizeof(T), out);
}

template <typename T>
void ReadColumn(Cursor& in, std::vector<T>& column) {
  in.Column(column, static_cast<std::size_t>(in.Value<std::uint64_t>()));
}

}  // namespace

void AppendPointSegment(std::uint32_t tag, const ParticleChunk& points, std::span<const std::uint32_t> indices,
                        const ParticleColumns& columns, Bytes& out) {
  AppendValue(tag, out);
  AppendValue<std::uint64_t>(indices.size(), out);
  AppendPicked(points.position, 3, indices, out);
  AppendPicked(points.mass, 1, indices, out);
  AppendPicked(points.type, 1, indices, out);
  if (columns.id) AppendPicked(points.id, 1, indices, out);
  if (columns.smoothing) AppendPicked(points.smoothing, 1, indices, out);
  const auto vectors = VectorColumns(points);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (columns.vectors[v]) AppendPicked(*vectors[v], 3, indices, out);
  }
}

ParticleChunk ReadPointSegment(std::span<const std::uint8_t> message, std::size_t& offset,
                               const ParticleColumns& columns, std::uint32_t& tag, const char* what) {
  Cursor in(message, offset, what);
  tag = in.Value<std::uint32_t>();
  const auto count = static_cast<std::size_t>(in.Value<std::uint64_t>());
  ParticleChunk points;
  in.Column(points.position, 3 * count);
  in.Column(points.mass, count);
  in.Column(points.type, count);
  if (columns.id) in.Column(points.id, count);
  if (columns.smoothing) in.Column(points.smoothing, count);
  const auto vectors = VectorColumns(points);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (columns.vectors[v]) in.Column(*vectors[v], 3 * count);
  }
  offset = in.offset();
  return points;
}

Bytes PackNode(NodeKey key, const NodePoints& points) {
  Bytes out;
  AppendValue(key.value(), out);
  AppendColumn(points.position, out);
  AppendColumn(points.weight, out);
  AppendColumn(points.smoothing, out);
  AppendColumn(points.id, out);
  AppendColumn(points.type, out);
  for (const std::vector<float>* column : VectorColumns(points)) AppendColumn(*column, out);
  AppendColumn(points.velocity_dispersion, out);
  AppendColumn(points.shape, out);
  AppendColumn(points.child_cluster, out);
  AppendColumn(points.refine_bound, out);
  AppendRaw(points.octant_offsets.data(), sizeof points.octant_offsets, out);
  AppendColumn(points.grid, out);
  return out;
}

NodePoints UnpackNode(std::span<const std::uint8_t> message, NodeKey& key, const char* what) {
  Cursor in(message, 0, what);
  key = NodeKey::FromValue(in.Value<std::uint64_t>());
  NodePoints points;
  ReadColumn(in, points.position);
  ReadColumn(in, points.weight);
  ReadColumn(in, points.smoothing);
  ReadColumn(in, points.id);
  ReadColumn(in, points.type);
  for (std::vector<float>* column : VectorColumns(points)) ReadColumn(in, *column);
  ReadColumn(in, points.velocity_dispersion);
  ReadColumn(in, points.shape);
  ReadColumn(in, points.child_cluster);
  ReadColumn(in, points.refine_bound);
  in.Read(points.octant_offsets.data(), sizeof points.octant_offsets);
  ReadColumn(in, points.grid);
  if (!in.done() || !key.IsValid()) throw Error::Corruption(what, "a node sent between ranks is malformed");
  return points;
}

}  // namespace octocosm
