// Writes a snapshot's particle positions as an uncompressed LAS 1.2 file, so
// that the ingest benchmark can run PotreeConverter (which reads LAS and LAZ
// only) on the same points as octocosm.
//
// Point data record format 0 (20 bytes: X, Y, Z as 32-bit integers, then
// intensity, return bits, classification, scan angle, user data and point
// source, all zero but "return 1 of 1"). The scale is the same on all three
// axes, the largest extent over 2^31 - 2 (so that every coordinate fits an
// int32), and the offset is the lower corner of the bounding box: positions
// come back to within half a scale unit. Two passes over the snapshot: the
// header needs the bounds before the first point.
#pragma once

#include <cstdint>
#include <string>

namespace octocosm {

struct LasExportReport {
  std::uint64_t points = 0;
  double scale = 0;
};

// Reads the snapshot at `snapshot` (any format OpenSnapshot reads) and writes
// `las_path`. Throws Error: kIo naming the file on a failed write, kInvalidArgument
// for a snapshot with more points than LAS 1.2 counts (2^32 - 1) or none.
LasExportReport ExportLas(const std::string& snapshot, const std::string& las_path);

}  // namespace octocosm
