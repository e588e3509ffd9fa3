#include "tools/query_output.h"

#include <array>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <sstream>
#include <type_traits>
#include <vector>

#include "base/error.h"
#include "index/cluster_shape.h"

namespace octocosm {
namespace {

bool Has(ColumnSet columns, ColumnId id) { return (columns & ColumnBit(id)) != 0; }

// The value of a column for point i, or zeros when the block lacks it.
template <typename T>
T At(const std::vector<T>& column, std::size_t index) {
  return index < column.size() ? column[index] : T{};
}

// Property names and PLY types, in output order.
struct Field {
  const char* name;
  const char* ply_type;
};

// The names of each vector column's three fields, indexed by VectorColumn.
constexpr std::array<std::array<const char*, 3>, kVectorColumnCount> kVectorFieldNames = {{
    {"vx", "vy", "vz"},
    {"dx", "dy", "dz"},
    {"nvx", "nvy", "nvz"},
    {"pdx", "pdy", "pdz"},
    {"pvx", "pvy", "pvz"},
}};

const std::array<const char*, 3>* VectorFieldNames(ColumnId id) {
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (kVectorColumnIds[v] == id) return &kVectorFieldNames[v];
  }
  return nullptr;
}

// Fields come in block column order (kColumnIds); position is always first.
std::vector<Field> FieldsOf(ColumnSet columns) {
  std::vector<Field> fields = {{"x", "double"}, {"y", "double"}, {"z", "double"}};
  for (const ColumnId id : kColumnIds) {
    if (id == ColumnId::kPosition || !Has(columns, id)) continue;
    if (const auto* names = VectorFieldNames(id)) {
      for (const char* n : *names) fields.push_back({n, "float"});
    } else if (id == ColumnId::kWeight || id == ColumnId::kSmoothing) {
      fields.push_back({ColumnName(id), "double"});
    } else if (id == ColumnId::kId) {
      fields.push_back({"id", "uint64"});  // see docs/QUERIES.md: a PLY extension
    } else if (id == ColumnId::kType) {
      fields.push_back({"type", "uchar"});
    } else if (id == ColumnId::kVelocityDispersion) {
      fields.push_back({ColumnName(id), "float"});
    } else if (id == ColumnId::kShape) {
      for (const char* n : {"shape_xx", "shape_yy", "shape_zz", "shape_xy", "shape_xz", "shape_yz"}) fields.push_back({n, "float"});
    }
  }
  return fields;
}

// Calls put(value) for each field of point i after its position, in the
// order of FieldsOf; a column the batch lacks gives zeros.
template <typename Put>
void ForEachExtraField(const NodePoints& p, std::size_t i, ColumnSet columns, const Put& put) {
  for (const ColumnId id : kColumnIds) {
    if (id == ColumnId::kPosition || !Has(columns, id)) continue;
    if (const std::vector<float>* vector = VectorColumnOf(p, id)) {
      for (int a = 0; a < 3; ++a) put(At(*vector, 3 * i + a));
    } else if (id == ColumnId::kWeight) {
      put(At(p.weight, i));
    } else if (id == ColumnId::kSmoothing) {
      put(At(p.smoothing, i));
    } else if (id == ColumnId::kId) {
      put(At(p.id, i));
    } else if (id == ColumnId::kType) {
      put(At(p.type, i));
    } else if (id == ColumnId::kVelocityDispersion) {
      put(At(p.velocity_dispersion, i));  // 0 for a leaf's particles, which carry none
    } else if (id == ColumnId::kShape) {
      // A leaf's particles, which carry none, are round.
      const SymmetricMatrix shape = 6 * i < p.shape.size() ? DecodeShape(ShapeCodeAt(p.shape, i)) : kRoundShape;
      for (const double entry : shape) put(static_cast<float>(entry));
    }
  }
}

template <typename T>
void PutLittleEndian(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));  // x86-64 and AArch64 Linux are little endian
  out.append(bytes, sizeof(T));
}

// Appends point i of the batch as binary little-endian fields.
void AppendBinary(const QueryBatch& batch, std::size_t i, ColumnSet columns, std::string& out) {
  const NodePoints& p = batch.points;
  for (int a = 0; a < 3; ++a) PutLittleEndian(out, p.position[3 * i + a]);
  ForEachExtraField(p, i, columns, [&](auto value) { PutLittleEndian(out, value); });
}

// Appends a number in the shortest form that reads back to the same value.
template <typename T>
void AppendNumber(T value, std::string& out) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
  out.append(buffer, result.ptr);
}

// Appends point i as text fields separated by `separator`.
void AppendText(const QueryBatch& batch, std::size_t i, ColumnSet columns, char separator, std::string& out) {
  const NodePoints& p = batch.points;
  const auto field = [&](auto value) {
    out += separator;
    AppendNumber(value, out);
  };
  AppendNumber(p.position[3 * i], out);
  field(p.position[3 * i + 1]);
  field(p.position[3 * i + 2]);
  ForEachExtraField(p, i, columns, [&](auto value) {
    if constexpr (std::is_same_v<decltype(value), std::uint8_t>) {
      field(static_cast<unsigned>(value));  // a number, not a character
    } else {
      field(value);
    }
  });
  out += '\n';
}

void WriteOrThrow(std::ostream& out, const std::string& bytes) {
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) throw Error::Io("query output", "write failed (disk full or closed pipe?)");
}

// A header, then each batch's records straight to the stream: CSV (a text
// line a point) or the binary format (fixed-size little-endian records).
class StreamWriter final : public PointWriter {
 public:
  using AppendRecord = void (*)(const QueryBatch& batch, std::size_t i, ColumnSet columns, std::string& out);
  StreamWriter(ColumnSet columns, std::ostream& out, const std::string& header, AppendRecord append)
      : columns_(columns), out_(out), append_(append) {
    WriteOrThrow(out_, header);
  }
  static std::unique_ptr<PointWriter> Csv(ColumnSet columns, std::ostream& out) {
    std::string header;
    for (const Field& f : FieldsOf(columns)) header += (header.empty() ? "" : ",") + std::string(f.name);
    return std::make_unique<StreamWriter>(columns, out, header + "\n",
                                          [](const QueryBatch& batch, std::size_t i, ColumnSet c, std::string& o) {
                                            AppendText(batch, i, c, ',', o);
                                          });
  }
  static std::unique_ptr<PointWriter> Binary(ColumnSet columns, std::ostream& out) {
    std::string header(kBinaryMagic, 4);
    PutLittleEndian(header, static_cast<std::uint32_t>(columns));
    PutLittleEndian(header, static_cast<std::uint32_t>(BinaryRecordSize(columns)));
    PutLittleEndian(header, std::uint32_t{0});
    return std::make_unique<StreamWriter>(columns, out, header, &AppendBinary);
  }
  void Write(const QueryBatch& batch) override {
    buffer_.clear();
    for (std::size_t i = 0; i < batch.count; ++i) append_(batch, i, columns_, buffer_);
    WriteOrThrow(out_, buffer_);
  }
  void Finish() override { out_.flush(); }

 private:
  ColumnSet columns_;
  std::ostream& out_;
  AppendRecord append_;
  std::string buffer_;
};

class PlyWriter final : public PointWriter {
 public:
  PlyWriter(ColumnSet columns, bool ascii, std::ostream& out)
      : columns_(columns), ascii_(ascii), out_(out), spool_(std::tmpfile()) {
    if (spool_ == nullptr) throw Error::Io("temporary file for the PLY body", std::strerror(errno));
  }
  ~PlyWriter() override {
    if (spool_ != nullptr) std::fclose(spool_);
  }
  void Write(const QueryBatch& batch) override {
    buffer_.clear();
    for (std::size_t i = 0; i < batch.count; ++i) {
      if (ascii_) AppendText(batch, i, columns_, ' ', buffer_);
      else AppendBinary(batch, i, columns_, buffer_);
    }
    if (std::fwrite(buffer_.data(), 1, buffer_.size(), spool_) != buffer_.size()) {
      throw Error::Io("temporary file for the PLY body", "write failed (disk full?)");
    }
    count_ += batch.count;
  }
  void Finish() override {
    std::string header = "ply\nformat ";
    header += ascii_ ? "ascii 1.0\n" : "binary_little_endian 1.0\n";
    header += "comment written by octocosm query\n";
    header += "element vertex " + std::to_string(count_) + "\n";
    for (const Field& f : FieldsOf(columns_)) header += std::string("property ") + f.ply_type + " " + f.name + "\n";
    header += "end_header\n";
    WriteOrThrow(out_, header);
    std::rewind(spool_);
    std::vector<char> chunk(1 << 20);
    std::size_t got;
    while ((got = std::fread(chunk.data(), 1, chunk.size(), spool_)) > 0) {
      out_.write(chunk.data(), static_cast<std::streamsize>(got));
      if (!out_) throw Error::Io("query output", "write failed (disk full or closed pipe?)");
    }
    if (std::ferror(spool_)) throw Error::Io("temporary file for the PLY body", "read failed");
    out_.flush();
  }

 private:
  ColumnSet columns_;
  bool ascii_;
  std::ostream& out_;
  std::FILE* spool_;
  std::uint64_t count_ = 0;
  std::string buffer_;
};

}  // namespace

PointFormat ParsePointFormat(const std::string& text) {
  if (text == "csv") return PointFormat::kCsv;
  if (text == "bin") return PointFormat::kBinary;
  if (text == "ply") return PointFormat::kPly;
  if (text == "ply-ascii") return PointFormat::kPlyAscii;
  throw Error::InvalidArgument("--format '" + text + "': expected csv, bin, ply or ply-ascii");
}

ColumnSet ParseColumnList(const std::string& text) {
  ColumnSet columns = ColumnBit(ColumnId::kPosition);
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    if (item.empty()) continue;
    if (item == "all") {
      columns |= kAllColumns;
      continue;
    }
    bool known = false;
    std::string names;
    for (const ColumnId id : kColumnIds) {
      if (kClusterLinkColumns & ColumnBit(id)) continue;  // a block's links, not a point's attributes
      names += std::string(ColumnName(id)) + ", ";
      if (item == ColumnName(id)) {
        columns |= ColumnBit(id);
        known = true;
      }
    }
    if (!known) throw Error::InvalidArgument("--columns: unknown column '" + item + "' (known: " + names + "all)");
  }
  return columns;
}

std::size_t BinaryRecordSize(ColumnSet columns) {
  std::size_t size = 24;
  const NodePoints none;
  ForEachExtraField(none, 0, columns, [&](auto value) { size += sizeof value; });
  return size;
}

std::unique_ptr<PointWriter> MakePointWriter(PointFormat format, ColumnSet columns, std::ostream& out) {
  columns = (columns & kAllColumns) | ColumnBit(ColumnId::kPosition);
  switch (format) {
    case PointFormat::kCsv: return StreamWriter::Csv(columns, out);
    case PointFormat::kBinary: return StreamWriter::Binary(columns, out);
    case PointFormat::kPly: return std::make_unique<PlyWriter>(columns, false, out);
    case PointFormat::kPlyAscii: return std::make_unique<PlyWriter>(columns, true, out);
  }
  throw Error::InvalidArgument("unknown output format");
}

}  // namespace octocosm
