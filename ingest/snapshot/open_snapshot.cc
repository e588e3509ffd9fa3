// OpenSnapshot: format detection and dispatch to the readers.
#include <cmath>
#include <cstring>

#include "base/error.h"
#include "ingest/snapshot/binary_file.h"
#include "ingest/snapshot/csv_source.h"
#include "ingest/snapshot/file_set.h"
#include "ingest/snapshot/gadget_format.h"
#include "ingest/snapshot/gadget_source.h"
#include "ingest/snapshot/hdf5_source.h"
#include "ingest/snapshot/raw_source.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {
namespace {

bool EndsWith(const std::string& text, const std::string& tail) {
  return text.size() >= tail.size() && text.compare(text.size() - tail.size(), tail.size(), tail) == 0;
}

// HDF5 files may start with a user block of 512, 1024, 2048... bytes; the
// signature is then at that offset.
bool HasHdf5Signature(const BinaryFile& file) {
  for (std::uint64_t offset = 0; offset + 8 <= file.size(); offset = offset == 0 ? 512 : offset * 2) {
    std::uint8_t bytes[8];
    file.ReadAt(offset, bytes, 8, "the HDF5 signature");
    if (IsHdf5Signature(bytes)) return true;
    if (offset >= (std::uint64_t{1} << 20)) break;
  }
  return false;
}

std::string DetectFormat(const std::string& file) {
  BinaryFile binary(file);
  if (binary.size() == 0) throw Error::BadInput(file, "empty input: the file has no bytes");
  if (HasHdf5Signature(binary)) return "hdf5";
  if (binary.size() >= 4) {
    std::uint8_t first[4];
    binary.ReadAt(0, first, 4, "the first record marker");
    if (SniffGadget(first)) return "gadget";
  }
  if (EndsWith(file, ".csv")) return "csv";
  throw Error::BadInput(file, "unrecognised snapshot format: neither HDF5 nor a GADGET binary (first record marker "
                              "256 or 8); for raw binary or CSV give the format explicitly");
}

}  // namespace

std::unique_ptr<ParticleSource> OpenSnapshot(const std::string& path, const ReadOptions& options) {
  if (options.chunk_particles == 0) throw Error::InvalidArgument("chunk_particles must be at least 1");
  for (int type : options.types) {
    if (type < 0 || type > 255) throw Error::InvalidArgument("particle type " + std::to_string(type) + " is not in 0..255");
  }
  if (!std::isfinite(options.box_size_override)) {
    throw Error::InvalidArgument("box_size_override must be a finite number (>= 0 for a box, negative for the header's)");
  }
  if (options.ignore_box && options.box_size_override >= 0) {
    throw Error::InvalidArgument("ignore_box and box_size_override contradict each other: give one");
  }
  std::string format = options.format;
  if (format == "raw" || format == "csv") {
    // Raw and CSV inputs are single files named exactly.
    if (format == "raw") return OpenRawSnapshot(path, options);
    return OpenCsvSnapshot(path, options);
  }
  std::string file = LocateSnapshotFile(path);
  if (format == "auto") format = DetectFormat(file);
  if (format == "gadget") return OpenGadgetSnapshot(file, options);
  if (format == "hdf5") return OpenHdf5Snapshot(file, options);
  if (format == "csv") return OpenCsvSnapshot(file, options);
  throw Error::InvalidArgument("unknown snapshot format \"" + options.format +
                               "\" (expected auto, gadget, hdf5, raw or csv)");
}

}  // namespace octocosm
