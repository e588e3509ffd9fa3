// RawLayout::Parse: the grammar is documented in snapshot_source.h and
// docs/INPUT_FORMATS.md.
#include <algorithm>
#include <map>

#include "base/error.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {
namespace {

using Field = RawColumn::Field;
using Scalar = RawColumn::Scalar;

std::size_t ScalarBytes(Scalar scalar) {
  switch (scalar) {
    case Scalar::kF32:
    case Scalar::kU32:
    case Scalar::kI32:
      return 4;
    case Scalar::kF64:
    case Scalar::kU64:
    case Scalar::kI64:
      return 8;
  }
  return 0;
}

std::string Trim(std::string_view text) {
  std::size_t begin = text.find_first_not_of(" \t");
  if (begin == std::string_view::npos) return "";
  std::size_t end = text.find_last_not_of(" \t");
  return std::string(text.substr(begin, end - begin + 1));
}

[[noreturn]] void Fail(std::string_view layout, const std::string& what) {
  throw Error::InvalidArgument("raw layout \"" + std::string(layout) + "\": " + what);
}

struct PendingColumn {
  std::string name;
  std::vector<Field> fields;  // the columns a name expands to ("skip" expands by its count)
  bool typed = false;
  Scalar scalar = Scalar::kF32;
  std::size_t count = 0;  // explicit "xN", 0 = none
};

}  // namespace

bool RawLayout::has(RawColumn::Field field) const {
  return std::any_of(columns.begin(), columns.end(), [&](const RawColumn& c) { return c.field == field; });
}

RawLayout RawLayout::Parse(std::string_view text) {
  static const std::map<std::string, std::vector<Field>> kNames = {
      {"x", {Field::kX}},
      {"y", {Field::kY}},
      {"z", {Field::kZ}},
      {"xyz", {Field::kX, Field::kY, Field::kZ}},
      {"pos", {Field::kX, Field::kY, Field::kZ}},
      {"vx", {Field::kVx}},
      {"vy", {Field::kVy}},
      {"vz", {Field::kVz}},
      {"vel", {Field::kVx, Field::kVy, Field::kVz}},
      {"mass", {Field::kMass}},
      {"id", {Field::kId}},
      {"skip", {Field::kSkip}},
  };
  static const std::map<std::string, Scalar> kScalars = {
      {"f32", Scalar::kF32}, {"f64", Scalar::kF64}, {"u32", Scalar::kU32},
      {"u64", Scalar::kU64}, {"i32", Scalar::kI32}, {"i64", Scalar::kI64},
  };

  RawLayout layout;
  layout.text = std::string(text);
  std::string_view body = text;
  std::string trimmed = Trim(body);
  body = trimmed;
  if (!body.empty() && (body.front() == '<' || body.front() == '>')) {
    layout.big_endian = body.front() == '>';
    body.remove_prefix(1);
  }
  if (Trim(body).empty()) Fail(text, "no columns");

  std::vector<PendingColumn> pending;
  std::size_t start = 0;
  while (start <= body.size()) {
    std::size_t comma = body.find(',', start);
    if (comma == std::string_view::npos) comma = body.size();
    std::string item = Trim(body.substr(start, comma - start));
    start = comma + 1;
    if (item.empty()) Fail(text, "empty column between commas");
    PendingColumn column;
    std::size_t colon = item.find(':');
    column.name = Trim(item.substr(0, colon));
    auto name = kNames.find(column.name);
    if (name == kNames.end()) Fail(text, "unknown column name \"" + column.name + "\"");
    column.fields = name->second;
    if (colon != std::string::npos) {
      std::string type = Trim(item.substr(colon + 1));
      std::size_t times = type.find('x');
      std::string scalar_name = type.substr(0, times);
      auto scalar = kScalars.find(scalar_name);
      if (scalar == kScalars.end()) {
        Fail(text, "unknown scalar type \"" + scalar_name + "\" for column " + column.name +
                       " (expected f32, f64, u32, u64, i32 or i64)");
      }
      column.typed = true;
      column.scalar = scalar->second;
      if (times != std::string::npos) {
        std::string digits = type.substr(times + 1);
        if (digits.empty() || digits.size() > 6 || digits.find_first_not_of("0123456789") != std::string::npos ||
            std::stoul(digits) == 0) {
          Fail(text, "bad repeat count \"" + digits + "\" for column " + column.name);
        }
        column.count = std::stoul(digits);
      }
    }
    if (column.count != 0) {
      if (column.name == "skip") {
        column.fields.assign(column.count, Field::kSkip);
      } else if (column.count != column.fields.size()) {
        Fail(text, "column " + column.name + " has " + std::to_string(column.fields.size()) +
                       " component(s), not " + std::to_string(column.count));
      }
    }
    pending.push_back(column);
    if (comma == body.size()) break;
  }

  // A type applies to its column and the untyped columns right before it.
  for (std::size_t i = pending.size(); i-- > 0;) {
    if (pending[i].typed) continue;
    if (i + 1 == pending.size()) Fail(text, "column " + pending[i].name + " has no scalar type (add e.g. :f32)");
    pending[i].scalar = pending[i + 1].scalar;
    pending[i].typed = true;
  }

  std::map<Field, int> seen;
  for (const PendingColumn& column : pending) {
    for (Field field : column.fields) {
      if (field != Field::kSkip && ++seen[field] > 1) Fail(text, "a column appears twice (" + column.name + ")");
      if (field == Field::kId && (column.scalar == Scalar::kF32 || column.scalar == Scalar::kF64)) {
        Fail(text, "id must be an integer type (u32, u64, i32, i64)");
      }
      layout.columns.push_back(RawColumn{field, column.scalar, layout.record_bytes});
      layout.record_bytes += ScalarBytes(column.scalar);
    }
  }
  if (!seen.count(Field::kX) || !seen.count(Field::kY) || !seen.count(Field::kZ)) {
    Fail(text, "x, y and z are required");
  }
  int velocity_components = static_cast<int>(seen.count(Field::kVx) + seen.count(Field::kVy) + seen.count(Field::kVz));
  if (velocity_components != 0 && velocity_components != 3) Fail(text, "give all of vx, vy, vz or none");
  return layout;
}

}  // namespace octocosm
