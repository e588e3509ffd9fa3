#include "tools/query_output.h"

#include <array>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <sstream>
#include <vector>

#include "storage/error.h"

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

std::vector<Field> FieldsOf(ColumnSet columns) {
  std::vector<Field> fields = {{"x", "double"}, {"y", "double"}, {"z", "double"}};
  if (Has(columns, ColumnId::kWeight)) fields.push_back({"weight", "double"});
  if (Has(columns, ColumnId::kSmoothing)) fields.push_back({"smoothing", "double"});
  if (Has(columns, ColumnId::kVelocity)) {
    for (const char* n : {"vx", "vy", "vz"}) fields.push_back({n, "float"});
  }
  if (Has(columns, ColumnId::kId)) fields.push_back({"id", "uint64"});  // see docs/QUERIES.md: a PLY extension
  if (Has(columns, ColumnId::kType)) fields.push_back({"type", "uchar"});
  if (Has(columns, ColumnId::kDisplacement)) {
    for (const char* n : {"dx", "dy", "dz"}) fields.push_back({n, "float"});
  }
  return fields;
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
  if (Has(columns, ColumnId::kWeight)) PutLittleEndian(out, At(p.weight, i));
  if (Has(columns, ColumnId::kSmoothing)) PutLittleEndian(out, At(p.smoothing, i));
  if (Has(columns, ColumnId::kVelocity)) {
    for (int a = 0; a < 3; ++a) PutLittleEndian(out, At(p.velocity, 3 * i + a));
  }
  if (Has(columns, ColumnId::kId)) PutLittleEndian(out, At(p.id, i));
  if (Has(columns, ColumnId::kType)) PutLittleEndian(out, At(p.type, i));
  if (Has(columns, ColumnId::kDisplacement)) {
    for (int a = 0; a < 3; ++a) PutLittleEndian(out, At(p.displacement, 3 * i + a));
  }
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
  if (Has(columns, ColumnId::kWeight)) field(At(p.weight, i));
  if (Has(columns, ColumnId::kSmoothing)) field(At(p.smoothing, i));
  if (Has(columns, ColumnId::kVelocity)) {
    for (int a = 0; a < 3; ++a) field(At(p.velocity, 3 * i + a));
  }
  if (Has(columns, ColumnId::kId)) field(At(p.id, i));
  if (Has(columns, ColumnId::kType)) field(static_cast<unsigned>(At(p.type, i)));
  if (Has(columns, ColumnId::kDisplacement)) {
    for (int a = 0; a < 3; ++a) field(At(p.displacement, 3 * i + a));
  }
  out += '\n';
}

void WriteOrThrow(std::ostream& out, const std::string& bytes) {
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) throw Error::Io("query output", "write failed (disk full or closed pipe?)");
}

class CsvWriter final : public PointWriter {
 public:
  CsvWriter(ColumnSet columns, std::ostream& out) : columns_(columns), out_(out) {
    std::string header;
    for (const Field& f : FieldsOf(columns)) header += (header.empty() ? "" : ",") + std::string(f.name);
    WriteOrThrow(out_, header + "\n");
  }
  void Write(const QueryBatch& batch) override {
    buffer_.clear();
    for (std::size_t i = 0; i < batch.count; ++i) AppendText(batch, i, columns_, ',', buffer_);
    WriteOrThrow(out_, buffer_);
  }
  void Finish() override { out_.flush(); }

 private:
  ColumnSet columns_;
  std::ostream& out_;
  std::string buffer_;
};

class BinaryWriter final : public PointWriter {
 public:
  BinaryWriter(ColumnSet columns, std::ostream& out) : columns_(columns), out_(out) {
    std::string header(kBinaryMagic, 4);
    PutLittleEndian(header, static_cast<std::uint32_t>(columns));
    PutLittleEndian(header, static_cast<std::uint32_t>(BinaryRecordSize(columns)));
    PutLittleEndian(header, std::uint32_t{0});
    WriteOrThrow(out_, header);
  }
  void Write(const QueryBatch& batch) override {
    buffer_.clear();
    for (std::size_t i = 0; i < batch.count; ++i) AppendBinary(batch, i, columns_, buffer_);
    WriteOrThrow(out_, buffer_);
  }
  void Finish() override { out_.flush(); }

 private:
  ColumnSet columns_;
  std::ostream& out_;
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
    for (ColumnId id : {ColumnId::kPosition, ColumnId::kWeight, ColumnId::kSmoothing, ColumnId::kVelocity, ColumnId::kId,
                        ColumnId::kType, ColumnId::kDisplacement}) {
      if (item == ColumnName(id)) {
        columns |= ColumnBit(id);
        known = true;
      }
    }
    if (!known) {
      throw Error::InvalidArgument("--columns: unknown column '" + item +
                                   "' (known: position, weight, smoothing, velocity, id, type, displacement, all)");
    }
  }
  return columns;
}

std::size_t BinaryRecordSize(ColumnSet columns) {
  std::size_t size = 24;
  if (Has(columns, ColumnId::kWeight)) size += 8;
  if (Has(columns, ColumnId::kSmoothing)) size += 8;
  if (Has(columns, ColumnId::kVelocity)) size += 12;
  if (Has(columns, ColumnId::kId)) size += 8;
  if (Has(columns, ColumnId::kType)) size += 1;
  if (Has(columns, ColumnId::kDisplacement)) size += 12;
  return size;
}

std::unique_ptr<PointWriter> MakePointWriter(PointFormat format, ColumnSet columns, std::ostream& out) {
  columns = (columns & kAllColumns) | ColumnBit(ColumnId::kPosition);
  switch (format) {
    case PointFormat::kCsv: return std::make_unique<CsvWriter>(columns, out);
    case PointFormat::kBinary: return std::make_unique<BinaryWriter>(columns, out);
    case PointFormat::kPly: return std::make_unique<PlyWriter>(columns, false, out);
    case PointFormat::kPlyAscii: return std::make_unique<PlyWriter>(columns, true, out);
  }
  throw Error::InvalidArgument("unknown output format");
}

}  // namespace octocosm
