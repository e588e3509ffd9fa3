#include "bench/las_export.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

#include "base/error.h"
#include "index/particle_chunk.h"
#include "storage/coding.h"
#include "storage/file.h"
#include "ingest/epoch_join.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {
namespace {

constexpr std::size_t kHeaderBytes = 227;  // LAS 1.2's public header block
constexpr std::size_t kRecordBytes = 20;   // point data record format 0
constexpr double kLargestCoordinate = 2147483646.0;  // 2^31 - 2

std::array<std::uint8_t, kHeaderBytes> Header(std::uint64_t points, double scale, const std::array<double, 3>& lo,
                                              const std::array<double, 3>& hi) {
  std::array<std::uint8_t, kHeaderBytes> h{};
  std::memcpy(h.data(), "LASF", 4);
  h[24] = 1;  // version 1.2
  h[25] = 2;
  const char software[] = "octocosm-bench-ingest";
  std::memcpy(h.data() + 58, software, sizeof software - 1);
  PutU16(h.data() + 94, kHeaderBytes);
  PutU32(h.data() + 96, kHeaderBytes);  // the points follow the header: no variable-length records
  h[104] = 0;                           // point data record format 0
  PutU16(h.data() + 105, kRecordBytes);
  PutU32(h.data() + 107, static_cast<std::uint32_t>(points));
  PutU32(h.data() + 111, static_cast<std::uint32_t>(points));  // all of them first returns
  for (int a = 0; a < 3; ++a) {
    PutF64(h.data() + 131 + 8 * a, scale);
    PutF64(h.data() + 155 + 8 * a, lo[a]);
    PutF64(h.data() + 179 + 16 * a, hi[a]);  // max, then min, per axis
    PutF64(h.data() + 187 + 16 * a, lo[a]);
  }
  return h;
}

}  // namespace

LasExportReport ExportLas(const std::string& snapshot, const std::string& las_path) {
  ReadOptions read;
  read.read_velocity = false;
  read.read_id = false;
  std::unique_ptr<ParticleSource> source = OpenSnapshot(snapshot, read);
  ParticleChunk chunk;

  Bounds bounds;
  while (source->Next(chunk)) bounds.Add(chunk);
  const std::uint64_t points = bounds.count;
  const std::array<double, 3>& lo = bounds.lo;
  const std::array<double, 3>& hi = bounds.hi;
  if (points == 0) throw Error::InvalidArgument("LAS export: snapshot " + snapshot + " holds no particles");
  if (points > std::numeric_limits<std::uint32_t>::max()) {
    throw Error::InvalidArgument("LAS export: snapshot " + snapshot + " holds " + std::to_string(points) +
                                 " particles, more than a LAS 1.2 file counts (2^32 - 1)");
  }
  const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  // Coincident points still need a non-zero scale.
  const double scale = extent > 0 ? extent / kLargestCoordinate : 1e-9;

  WritableFile out = WritableFile::Create(las_path);
  const auto header = Header(points, scale, lo, hi);
  out.Append(header);
  source->Rewind();
  std::vector<std::uint8_t> records;
  std::uint64_t written = 0;
  while (source->Next(chunk)) {
    records.assign(chunk.size() * kRecordBytes, 0);
    for (std::size_t i = 0; i < chunk.size(); ++i) {
      std::uint8_t* record = records.data() + i * kRecordBytes;
      for (int a = 0; a < 3; ++a) {
        const double units = std::round((chunk.position[3 * i + a] - lo[a]) / scale);
        PutU32(record + 4 * a, static_cast<std::uint32_t>(static_cast<std::int32_t>(std::min(units, kLargestCoordinate))));
      }
      record[14] = 0x09;  // return 1 of 1
    }
    out.Append(records);
    written += chunk.size();
  }
  if (written != points) {
    throw Error::Io(snapshot, "read " + std::to_string(written) + " particles on the second pass, " +
                                  std::to_string(points) + " on the first");
  }
  out.Close();
  return {points, scale};
}

}  // namespace octocosm
