#include "ingest/snapshot/csv_source.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <fstream>
#include <map>

#include "base/error.h"
#include "ingest/snapshot/file_set.h"
#include "ingest/snapshot/segmented_source.h"

namespace octocosm {
namespace {

std::string_view TrimView(std::string_view text) {
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.front()))) text.remove_prefix(1);
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.remove_suffix(1);
  return text;
}

bool IsSkippable(std::string_view line) {
  std::string_view trimmed = TrimView(line);
  return trimmed.empty() || trimmed.front() == '#';
}

// Splits a line on `delimiter` (',' exactly, ' ' = runs of blanks).
void SplitFields(std::string_view line, char delimiter, std::vector<std::string_view>& fields) {
  fields.clear();
  if (delimiter == ',') {
    std::size_t start = 0;
    while (true) {
      std::size_t comma = line.find(',', start);
      fields.push_back(TrimView(line.substr(start, comma == std::string_view::npos ? line.npos : comma - start)));
      if (comma == std::string_view::npos) break;
      start = comma + 1;
    }
    return;
  }
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    std::size_t start = i;
    while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > start) fields.push_back(line.substr(start, i - start));
  }
}

enum Column { kX, kY, kZ, kVx, kVy, kVz, kMass, kId, kColumnCount };

class CsvSource final : public SegmentedSource {
 public:
  CsvSource(const std::string& path, const ReadOptions& options)
      : SegmentedSource(options.chunk_particles), path_(path), delimiter_(options.csv.delimiter) {
    if (delimiter_ != 0 && delimiter_ != ',' && delimiter_ != ' ') {
      throw Error::InvalidArgument("CSV delimiter must be ',' or ' ' (whitespace)");
    }
    RequireRegularFile(path);
    stream_.open(path, std::ios::binary);
    if (!stream_) {
      int error = errno;
      if (error == ENOENT) throw Error::NotFound("CSV file " + path);
      throw IoErrorFromErrno(path, "open", error);
    }
    ReadHeaderRow();
    header_.format = "csv";
    header_.files = {path};
    header_.has_velocity = options.read_velocity && index_[kVx] >= 0;
    header_.has_id = options.read_id && index_[kId] >= 0;
    SetBoxSize(path, "BoxSize", 0, options);  // no header: periodic only when given
    header_.extra["csv_columns"] = names_;

    // Validate every row and count them, so that the header is exact before
    // the first chunk is read.
    std::uint64_t rows = 0;
    ParticleChunk scratch;
    while (ReadRow(scratch)) {
      ++rows;
      scratch.clear();
    }
    if (rows == 0) throw Error::BadInput(path, "empty input: the CSV has a header row but no particle rows");
    if (IsTypeSelected(options.types, 0)) segments_.push_back(Segment{0, 0, rows});
    CountSegments(1);
    OnRewind();
  }

 protected:
  void AppendRange(const Segment&, std::uint64_t, std::size_t count, ParticleChunk& chunk) override {
    for (std::size_t i = 0; i < count; ++i) {
      if (!ReadRow(chunk)) throw Error::BadInput(path_, "the file changed while it was read (fewer rows than counted)");
    }
  }

  bool SeeksRanges() const override { return false; }  // rows are found by reading the lines before them

  void OnRewind() override {
    stream_.clear();
    stream_.seekg(data_start_);
    line_number_ = data_start_line_;
  }

 private:
  [[noreturn]] void FailAt(const std::string& what) const {
    throw Error::BadInput(path_, "line " + std::to_string(line_number_) + ": " + what);
  }

  bool GetLine() {
    if (!std::getline(stream_, line_)) {
      if (stream_.bad()) throw IoErrorFromErrno(path_, "read", errno);
      return false;
    }
    ++line_number_;
    if (!line_.empty() && line_.back() == '\r') line_.pop_back();
    return true;
  }

  void ReadHeaderRow() {
    line_number_ = 0;
    do {
      if (!GetLine()) throw Error::BadInput(path_, "empty input: no header row naming the columns");
    } while (IsSkippable(line_));
    if (delimiter_ == 0) delimiter_ = line_.find(',') != std::string::npos ? ',' : ' ';
    SplitFields(line_, delimiter_, fields_);
    static const std::map<std::string, Column> kKnown = {{"x", kX},   {"y", kY},   {"z", kZ},       {"vx", kVx},
                                                         {"vy", kVy}, {"vz", kVz}, {"mass", kMass}, {"id", kId}};
    std::fill(std::begin(index_), std::end(index_), -1);
    for (std::size_t i = 0; i < fields_.size(); ++i) {
      std::string name(fields_[i]);
      if (name.size() >= 2 && name.front() == '"' && name.back() == '"') name = name.substr(1, name.size() - 2);
      std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return std::tolower(c); });
      names_.push_back(name);
      auto known = kKnown.find(name);
      if (known == kKnown.end()) continue;
      if (index_[known->second] >= 0) FailAt("column \"" + name + "\" appears twice in the header row");
      index_[known->second] = static_cast<int>(i);
    }
    for (Column required : {kX, kY, kZ}) {
      if (index_[required] < 0) {
        FailAt("the header row must name columns x, y and z (found: " + line_.substr(0, 200) + ")");
      }
    }
    int velocity = (index_[kVx] >= 0) + (index_[kVy] >= 0) + (index_[kVz] >= 0);
    if (velocity != 0 && velocity != 3) FailAt("the header row must name all of vx, vy, vz or none");
    data_start_ = stream_.tellg();
    data_start_line_ = line_number_;
  }

  double ParseReal(Column column) {
    std::string_view text = fields_[static_cast<std::size_t>(index_[column])];
    double value = 0;
    auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (error != std::errc() || end != text.data() + text.size()) {
      FailAt("column " + names_[static_cast<std::size_t>(index_[column])] + ": cannot read \"" +
             std::string(text.substr(0, 40)) + "\" as a number");
    }
    return value;
  }

  // Appends the next particle row to `chunk`; false at the end of the file.
  bool ReadRow(ParticleChunk& chunk) {
    do {
      if (!GetLine()) return false;
    } while (IsSkippable(line_));
    SplitFields(line_, delimiter_, fields_);
    if (fields_.size() != names_.size()) {
      FailAt(std::to_string(fields_.size()) + " fields, but the header row names " + std::to_string(names_.size()));
    }
    double position[3] = {ParseReal(kX), ParseReal(kY), ParseReal(kZ)};
    if (!std::isfinite(position[0]) || !std::isfinite(position[1]) || !std::isfinite(position[2])) {
      FailAt("non-finite coordinate; positions must be finite numbers");
    }
    chunk.position.insert(chunk.position.end(), position, position + 3);
    if (FillsVelocity()) {
      for (Column c : {kVx, kVy, kVz}) {
        const auto v = static_cast<float>(ParseReal(c));
        if (!std::isfinite(v)) FailAt("non-finite velocity; velocities must be finite numbers");
        chunk.velocity.push_back(v);
      }
    }
    const double mass = index_[kMass] >= 0 ? ParseReal(kMass) : 1.0;
    if (!std::isfinite(mass) || !(mass > 0)) {
      FailAt("mass " + std::to_string(mass) + "; masses must be finite and > 0");
    }
    chunk.mass.push_back(mass);
    if (FillsId()) {
      std::string_view text = fields_[static_cast<std::size_t>(index_[kId])];
      std::uint64_t id = 0;
      auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), id);
      if (error != std::errc() || end != text.data() + text.size()) {
        FailAt("column id: cannot read \"" + std::string(text.substr(0, 40)) + "\" as an unsigned integer");
      }
      chunk.id.push_back(id);
    }
    chunk.type.push_back(0);
    return true;
  }

  std::string path_;
  char delimiter_;
  std::ifstream stream_;
  std::string line_;
  std::vector<std::string_view> fields_;
  std::vector<std::string> names_;
  int index_[kColumnCount];
  std::streampos data_start_;
  std::uint64_t line_number_ = 0, data_start_line_ = 0;
};

}  // namespace

std::unique_ptr<ParticleSource> OpenCsvSnapshot(const std::string& file, const ReadOptions& options) {
  return std::make_unique<CsvSource>(file, options);
}

}  // namespace octocosm
