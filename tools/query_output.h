// Writers for the points a query returns: CSV, raw binary and PLY
// (docs/QUERIES.md describes each byte). A writer receives the batches of
// query/query.h as they arrive and never holds more than one batch, except
// that PLY, whose header must state the point count, spools its body to a
// temporary file until Finish.
#pragma once

#include <cstdint>
#include <cstdio>
#include <memory>
#include <ostream>
#include <string>

#include "index/block_codec.h"
#include "query/query.h"

namespace octocosm {

enum class PointFormat { kCsv, kBinary, kPly, kPlyAscii };

// "csv", "bin", "ply" (binary little endian), "ply-ascii"; throws
// Error::InvalidArgument naming --format otherwise.
PointFormat ParsePointFormat(const std::string& text);
// "weight,velocity,id" -> column bits (position always included); "all" is
// every column. Throws Error::InvalidArgument naming --columns.
ColumnSet ParseColumnList(const std::string& text);

class PointWriter {
 public:
  virtual ~PointWriter() = default;
  virtual void Write(const QueryBatch& batch) = 0;
  // Completes the output (PLY writes its header and body here).
  virtual void Finish() = 0;
};

// Writes to `out` (which must outlive the writer). Columns: position plus
// those in `columns`, in the block column order (kColumnIds: position,
// weight, smoothing, velocity, id, type, displacement, next_velocity,
// prev_displacement, prev_velocity). A wanted optional column that a block
// lacks (a store without velocities, say) is written as zeros.
std::unique_ptr<PointWriter> MakePointWriter(PointFormat format, ColumnSet columns, std::ostream& out);

// The 16-byte header of the raw binary format: "OCQ1", u32 column bits,
// u32 record size, u32 reserved 0; then records until the end.
inline constexpr char kBinaryMagic[4] = {'O', 'C', 'Q', '1'};
std::size_t BinaryRecordSize(ColumnSet columns);

}  // namespace octocosm
