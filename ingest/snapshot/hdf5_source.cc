#include "ingest/snapshot/hdf5_source.h"

#include <hdf5.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <numbers>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "base/error.h"
#include "ingest/snapshot/binary_file.h"
#include "ingest/snapshot/file_set.h"
#include "ingest/snapshot/isolated_process.h"
#include "ingest/snapshot/segmented_source.h"

namespace octocosm {
namespace {

// Owns one HDF5 identifier and closes it with the matching H5?close.
class Handle {
 public:
  Handle() = default;
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Handle() { Reset(); }
  Handle(Handle&& other) noexcept : id_(std::exchange(other.id_, H5I_INVALID_HID)), close_(other.close_) {}
  Handle& operator=(Handle&& other) noexcept {
    if (this != &other) {
      Reset();
      id_ = std::exchange(other.id_, H5I_INVALID_HID);
      close_ = other.close_;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;

  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }
  void Reset() {
    if (id_ >= 0 && close_ != nullptr) close_(id_);
    id_ = H5I_INVALID_HID;
  }

 private:
  hid_t id_ = H5I_INVALID_HID;
  herr_t (*close_)(hid_t) = nullptr;
};

// The most specific description on the HDF5 error stack, then clears it.
std::string TakeHdf5ErrorDetail() {
  std::string detail;
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_DOWNWARD,
      [](unsigned, const H5E_error2_t* error, void* data) -> herr_t {
        if (error->desc != nullptr && error->desc[0] != '\0') *static_cast<std::string*>(data) = error->desc;
        return 0;
      },
      &detail);
  H5Eclear2(H5E_DEFAULT);
  return detail;
}

[[noreturn]] void ThrowHdf5(const std::string& path, const std::string& what) {
  std::string detail = TakeHdf5ErrorDetail();
  throw Error::BadInput(path, what + (detail.empty() ? "" : " (HDF5: " + detail + ")"));
}

void SilenceHdf5ErrorPrinting() {
  // HDF5 prints its error stack to stderr by default; we report errors ourselves.
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
}

Handle OpenFile(const std::string& path) {
  // In the child of OpenHdf5Snapshot: names the file that libhdf5 reads from
  // here on, should it crash.
  NoteIsolatedProgress(path);
  hid_t id = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (id < 0) ThrowHdf5(path, "cannot open as HDF5 (truncated or damaged file?)");
  return Handle(id, H5Fclose);
}

bool LinkExists(hid_t location, const std::string& name) {
  htri_t exists = H5Lexists(location, name.c_str(), H5P_DEFAULT);
  if (exists < 0) H5Eclear2(H5E_DEFAULT);
  return exists > 0;
}

// Opens a group or dataset, or returns an invalid handle when it is absent.
Handle OpenGroupIfPresent(hid_t file, const std::string& name, const std::string& path) {
  if (!LinkExists(file, name)) return Handle();
  hid_t id = H5Gopen2(file, name.c_str(), H5P_DEFAULT);
  if (id < 0) ThrowHdf5(path, "cannot open group /" + name);
  return Handle(id, H5Gclose);
}

// Reads a numeric attribute of any length (SWIFT writes scalars as 1-element
// arrays) as `memory_type`; nullopt when absent.
template <typename T>
std::optional<std::vector<T>> ReadAttribute(hid_t object, const char* name, hid_t memory_type,
                                            const std::string& path, const std::string& group) {
  htri_t exists = H5Aexists(object, name);
  if (exists < 0) ThrowHdf5(path, "cannot look up attribute " + group + "/" + name);
  if (exists == 0) return std::nullopt;
  std::string where = "attribute " + group + "/" + name;
  Handle attribute(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  if (!attribute.valid()) ThrowHdf5(path, "cannot open " + where);
  Handle type(H5Aget_type(attribute.get()), H5Tclose);
  H5T_class_t type_class = H5Tget_class(type.get());
  if (type_class != H5T_INTEGER && type_class != H5T_FLOAT) {
    throw Error::BadInput(path, where + " is not numeric");
  }
  Handle space(H5Aget_space(attribute.get()), H5Sclose);
  hssize_t points = H5Sget_simple_extent_npoints(space.get());
  if (points < 0 || points > 1 << 20) ThrowHdf5(path, "cannot size " + where);
  std::vector<T> values(static_cast<std::size_t>(points));
  if (points > 0 && H5Aread(attribute.get(), memory_type, values.data()) < 0) ThrowHdf5(path, "cannot read " + where);
  return values;
}

std::optional<std::vector<double>> ReadDoubles(hid_t object, const char* name, const std::string& path,
                                               const std::string& group) {
  return ReadAttribute<double>(object, name, H5T_NATIVE_DOUBLE, path, group);
}

// Reads a count attribute (particle and file counts) as unsigned integers.
// Stored as signed integers or floats (as some writers do), each value must be
// a whole number >= 0: HDF5's conversion would otherwise make -1 a 0 and 2.5
// a 2 without a word.
std::optional<std::vector<std::uint64_t>> ReadCounts(hid_t object, const char* name, const std::string& path,
                                                     const std::string& group) {
  htri_t exists = H5Aexists(object, name);
  if (exists < 0) ThrowHdf5(path, "cannot look up attribute " + group + "/" + name);
  if (exists == 0) return std::nullopt;
  const std::string where = "attribute " + group + "/" + name;
  H5T_class_t type_class = H5T_NO_CLASS;
  H5T_sign_t sign = H5T_SGN_NONE;
  {
    Handle attribute(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
    if (!attribute.valid()) ThrowHdf5(path, "cannot open " + where);
    Handle type(H5Aget_type(attribute.get()), H5Tclose);
    type_class = H5Tget_class(type.get());
    if (type_class == H5T_INTEGER) sign = H5Tget_sign(type.get());
  }
  if (type_class == H5T_INTEGER && sign == H5T_SGN_NONE) {
    return ReadAttribute<std::uint64_t>(object, name, H5T_NATIVE_UINT64, path, group);
  }
  std::optional<std::vector<double>> values;
  std::optional<std::vector<std::int64_t>> signed_values;
  if (type_class == H5T_INTEGER) {
    signed_values = ReadAttribute<std::int64_t>(object, name, H5T_NATIVE_INT64, path, group);
  } else {
    values = ReadAttribute<double>(object, name, H5T_NATIVE_DOUBLE, path, group);
  }
  std::vector<std::uint64_t> counts;
  const std::size_t n = signed_values ? signed_values->size() : values->size();
  for (std::size_t i = 0; i < n; ++i) {
    const double value = signed_values ? static_cast<double>((*signed_values)[i]) : (*values)[i];
    if (!(value >= 0 && value < 0x1p63 && value == std::floor(value))) {
      std::ostringstream text;
      text << value;
      throw Error::BadInput(path, where + " holds " + text.str() + " at index " + std::to_string(i) +
                                      "; a count must be a whole number >= 0");
    }
    counts.push_back(signed_values ? static_cast<std::uint64_t>((*signed_values)[i])
                                   : static_cast<std::uint64_t>(value));
  }
  return counts;
}

// First element of an optional attribute; `fallback` when absent or empty.
double FirstOr(const std::optional<std::vector<double>>& values, double fallback) {
  return values && !values->empty() ? values->front() : fallback;
}

// An HDF5 file's declared shapes are checked against its size before
// libhdf5 reads a value (docs/INPUT_FORMATS.md): a dataset cannot hold more
// bytes than the file, and a compressed one no more than this many times the
// bytes it has stored. Deflate's own limit is about 1032:1, so no real
// dataset comes near; a dataset declaring more has chunks that were never
// written (HDF5 would hand out fill values) or a count that is not true, and
// reading it could take hours.
constexpr double kMaxCompressionRatio = 2048;
// The largest chunk libhdf5 may allocate for one read of a chunked dataset
// (real files use a few MiB).
constexpr std::uint64_t kMaxChunkBytes = std::uint64_t{256} << 20;

// Shape and element type of one dataset, checked against what we expect.
struct DatasetShape {
  bool present = false;
  int rank = 0;
  hsize_t rows = 0, columns = 1;
  bool is_signed = false;  // a signed integer type
};

// Opens dataset `name` and checks its element type (integers of 1 to 8
// bytes, or, unless `integer_only`, floats of 4 or 8) and rank (1 or 2).
Handle OpenDatasetChecked(hid_t file, const std::string& name, const std::string& path, bool integer_only,
                          DatasetShape& shape) {
  Handle dataset(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!dataset.valid()) ThrowHdf5(path, "cannot open dataset /" + name);
  Handle type(H5Dget_type(dataset.get()), H5Tclose);
  const H5T_class_t type_class = H5Tget_class(type.get());
  const std::size_t size = H5Tget_size(type.get());
  const bool integer = type_class == H5T_INTEGER && (size == 1 || size == 2 || size == 4 || size == 8);
  const bool real = type_class == H5T_FLOAT && (size == 4 || size == 8);
  if (!integer && (integer_only || !real)) {
    throw Error::BadInput(path, "dataset /" + name + " has elements of class " + std::to_string(type_class) + ", " +
                                    std::to_string(size) + " bytes; expected " +
                                    (integer_only ? "integers of 1 to 8 bytes" : "integers of 1 to 8 bytes or floats of 4 or 8"));
  }
  shape.is_signed = integer && H5Tget_sign(type.get()) == H5T_SGN_2;
  Handle space(H5Dget_space(dataset.get()), H5Sclose);
  int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 1 || rank > 2) {
    throw Error::BadInput(path, "dataset /" + name + " has rank " + std::to_string(rank) + "; expected 1 or 2");
  }
  hsize_t dims[2] = {0, 1};
  H5Sget_simple_extent_dims(space.get(), dims, nullptr);
  shape.present = true;
  shape.rank = rank;
  shape.rows = dims[0];
  shape.columns = rank == 2 ? dims[1] : 1;
  return dataset;
}

// Checks where an opened dataset keeps its values, before anything reads
// them: in this file (not a virtual dataset, not external raw files, whose
// names the file could point anywhere), with only the filters built into
// libhdf5 that particle data use, in chunks of at most kMaxChunkBytes, and
// in no more bytes than the file has (file_bytes), and, compressed, no more
// than kMaxCompressionRatio times what it stores.
void CheckDatasetStorage(const Handle& dataset, const std::string& name, const std::string& path,
                         std::uint64_t file_bytes, const DatasetShape& shape) {
  const std::string where = "dataset /" + name;
  Handle type(H5Dget_type(dataset.get()), H5Tclose);
  const double element_bytes = static_cast<double>(H5Tget_size(type.get()));
  const double values_bytes = static_cast<double>(shape.rows) * static_cast<double>(shape.columns) * element_bytes;
  Handle plist(H5Dget_create_plist(dataset.get()), H5Pclose);
  if (!plist.valid()) ThrowHdf5(path, "cannot read the storage properties of " + where);
  const H5D_layout_t layout = H5Pget_layout(plist.get());
  if (layout != H5D_COMPACT && layout != H5D_CONTIGUOUS && layout != H5D_CHUNKED) {
    throw Error::BadInput(path, where + " is not stored in this file (layout " + std::to_string(layout) +
                                    ", e.g. a virtual dataset); only compact, contiguous and chunked datasets are read");
  }
  if (H5Pget_external_count(plist.get()) != 0) {
    throw Error::BadInput(path, where + " keeps its values in external files; only values stored in the snapshot "
                                        "file itself are read");
  }
  bool compressed = false;
  const int filters = H5Pget_nfilters(plist.get());
  if (filters < 0) ThrowHdf5(path, "cannot list the filters of " + where);
  for (int f = 0; f < filters; ++f) {
    unsigned flags = 0;
    std::size_t parameters = 0;
    char filter_name[64] = {};
    unsigned config = 0;
    const H5Z_filter_t filter = H5Pget_filter2(plist.get(), static_cast<unsigned>(f), &flags, &parameters, nullptr,
                                               sizeof filter_name, filter_name, &config);
    if (filter == H5Z_FILTER_DEFLATE || filter == H5Z_FILTER_NBIT || filter == H5Z_FILTER_SCALEOFFSET) {
      compressed = true;
    } else if (filter != H5Z_FILTER_SHUFFLE && filter != H5Z_FILTER_FLETCHER32) {
      throw Error::BadInput(path, where + " uses filter " + std::to_string(filter) + " (" + filter_name +
                                      "); only deflate, shuffle, fletcher32, nbit and scaleoffset are read");
    }
  }
  if (layout == H5D_CHUNKED) {
    hsize_t chunk[2] = {0, 0};
    const int rank = H5Pget_chunk(plist.get(), 2, chunk);
    double chunk_bytes = element_bytes;
    for (int a = 0; a < rank && a < 2; ++a) chunk_bytes *= static_cast<double>(chunk[a]);
    if (rank < 1 || chunk_bytes > static_cast<double>(kMaxChunkBytes)) {
      throw Error::BadInput(path, where + " is stored in chunks of " + std::to_string(chunk_bytes) +
                                      " bytes; at most " + std::to_string(kMaxChunkBytes) + " are read");
    }
    // Counting the chunks walks the whole chunk index (its B-tree), which
    // reads of the data would otherwise first walk part by part: in the
    // child of OpenHdf5Snapshot, a damaged index fails here.
    hsize_t chunks = 0;
    Handle space(H5Dget_space(dataset.get()), H5Sclose);
    if (H5Dget_num_chunks(dataset.get(), space.get(), &chunks) < 0) {
      ThrowHdf5(path, "cannot walk the chunk index of " + where);
    }
    double grid = 1;
    const hsize_t extent[2] = {shape.rows, shape.columns};
    for (int a = 0; a < rank && a < 2; ++a) {
      grid *= chunk[a] == 0 ? 0 : std::ceil(static_cast<double>(extent[a]) / static_cast<double>(chunk[a]));
    }
    if (static_cast<double>(chunks) > grid) {
      throw Error::BadInput(path, where + "'s chunk index lists " + std::to_string(chunks) +
                                      " chunks; its shape has room for " +
                                      std::to_string(static_cast<std::uint64_t>(grid)));
    }
  }
  if (values_bytes == 0) return;
  const double stored = static_cast<double>(H5Dget_storage_size(dataset.get()));
  H5Eclear2(H5E_DEFAULT);
  auto refuse = [&](const std::string& why) {
    throw Error::BadInput(path, "counts do not add up: " + where + " declares " + std::to_string(shape.rows) +
                                    " x " + std::to_string(shape.columns) + " values (" +
                                    std::to_string(static_cast<std::uint64_t>(values_bytes)) + " bytes) but " + why);
  };
  if (stored == 0) refuse("stores none of them (never written)");
  if (stored > static_cast<double>(file_bytes)) {
    refuse("claims " + std::to_string(static_cast<std::uint64_t>(stored)) + " bytes of storage in a file of " +
           std::to_string(file_bytes) + " bytes");
  }
  if (!compressed && stored < values_bytes) {
    refuse("stores only " + std::to_string(static_cast<std::uint64_t>(stored)) + " bytes");
  }
  if (values_bytes > kMaxCompressionRatio * stored) {
    refuse("stores only " + std::to_string(static_cast<std::uint64_t>(stored)) + " bytes, more than " +
           std::to_string(static_cast<int>(kMaxCompressionRatio)) +
           ":1 compressed (chunks never written, or a false count)");
  }
}

// Checks that dataset `name` has `rows` x `columns` values stored in the
// file (CheckDatasetStorage); false when absent. `is_signed`, when given,
// is set to whether its elements are signed integers.
bool CheckDataset(hid_t file, const std::string& name, const std::string& path, std::uint64_t file_bytes,
                  std::uint64_t rows, hsize_t columns, bool integer_only, bool* is_signed = nullptr) {
  if (!LinkExists(file, name)) return false;
  DatasetShape shape;
  Handle dataset = OpenDatasetChecked(file, name, path, integer_only, shape);
  if (shape.rows != rows || shape.columns != columns) {
    throw Error::BadInput(path, "counts do not add up: dataset /" + name + " has " + std::to_string(shape.rows) +
                                    " x " + std::to_string(shape.columns) + " values; the header's NumPart_ThisFile "
                                    "declares " + std::to_string(rows) + " particles, so expected " +
                                    std::to_string(rows) + " x " + std::to_string(columns));
  }
  CheckDatasetStorage(dataset, name, path, file_bytes, shape);
  if (is_signed != nullptr) *is_signed = shape.is_signed;
  return true;
}

struct Hdf5File {
  std::string path;
  std::vector<std::uint64_t> this_file;  // NumPart_ThisFile
  std::vector<double> mass_table;        // MassTable, zeros when absent
  std::vector<bool> has_masses;          // per type: a Masses dataset is present
  std::vector<bool> signed_ids;          // per type: ParticleIDs holds signed integers (negatives are refused)
  // The name of PartType0's smoothing length dataset ("SmoothingLength" in
  // GADGET-4 and AREPO, "SmoothingLengths" in SWIFT); empty when it has none
  // or none is read.
  std::string smoothing_dataset;
};

// SWIFT's h is not the radius of the kernel's support H but H / gamma, with
// gamma fixed by the kernel; SWIFT records its kernel's target number of
// neighbours N = (4 pi / 3) (gamma eta)^3 and eta in /HydroScheme, from
// which gamma follows (1.825742 for its default cubic spline). nullopt when
// either is missing or makes no sense.
std::optional<double> SwiftKernelGamma(hid_t file, const std::string& path) {
  Handle scheme = OpenGroupIfPresent(file, "HydroScheme", path);
  if (!scheme.valid()) return std::nullopt;
  const auto neighbours = ReadDoubles(scheme.get(), "Kernel target N_ngb", path, "/HydroScheme");
  const auto eta = ReadDoubles(scheme.get(), "Kernel eta", path, "/HydroScheme");
  if (!neighbours || neighbours->empty() || !eta || eta->empty()) return std::nullopt;
  const double gamma = std::cbrt(3 * neighbours->front() / (4 * std::numbers::pi)) / eta->front();
  if (!std::isfinite(gamma) || !(gamma > 0)) return std::nullopt;
  return gamma;
}

std::string GroupName(int type) { return "PartType" + std::to_string(type); }

[[noreturn]] void ThrowAnswered(std::string_view answer);

class Hdf5Source final : public SegmentedSource {
 public:
  // Walks the snapshot's structure with libhdf5: every file's header and
  // datasets (DescribeFile), the first file's header numbers (FillHeader)
  // and smoothing lengths (FindSmoothing).
  Hdf5Source(const std::string& any_file, const ReadOptions& options) : SegmentedSource(options.chunk_particles) {
    SilenceHdf5ErrorPrinting();
    long long declared = 1;
    {
      Handle file = OpenFile(any_file);
      Handle group = RequireHeader(file.get(), any_file);
      auto files = ReadCounts(group.get(), "NumFilesPerSnapshot", any_file, "/Header");
      if (files && !files->empty()) declared = static_cast<long long>(std::min<std::uint64_t>(files->front(), 1u << 30));
    }
    std::vector<std::string> paths = ExpandFileSet(any_file, declared);
    read_velocity_ = options.read_velocity;
    read_id_ = options.read_id;
    read_smoothing_ = options.read_smoothing;
    bool all_velocity = true, all_id = true;
    for (std::size_t f = 0; f < paths.size(); ++f) {
      files_.push_back(DescribeFile(paths[f], options.types, all_velocity, all_id));
      header_.files.push_back(paths[f]);
      if (f > 0 && files_[f].this_file.size() != files_[0].this_file.size()) {
        throw Error::BadInput(paths[f], "NumPart_ThisFile has " + std::to_string(files_[f].this_file.size()) +
                                            " types but " + paths[0] + " has " +
                                            std::to_string(files_[0].this_file.size()));
      }
    }
    header_.has_velocity = options.read_velocity && all_velocity;
    header_.has_id = options.read_id && all_id;
    FillHeader(options);
    FindSmoothing(options);
  }

  // A source from what the walk above found (State()), without asking
  // libhdf5 again, that has `reader` (the process that walked) read its
  // particles: the owner's side of OpenHdf5Snapshot.
  Hdf5Source(const nlohmann::json& state, const ReadOptions& options, std::unique_ptr<IsolatedProcess> reader)
      : SegmentedSource(options.chunk_particles), reader_(std::move(reader)) {
    read_velocity_ = options.read_velocity;
    read_id_ = options.read_id;
    read_smoothing_ = options.read_smoothing;
    for (const nlohmann::json& f : state.at("files")) {
      Hdf5File file;
      file.path = f.at("path").get<std::string>();
      file.this_file = f.at("this_file").get<std::vector<std::uint64_t>>();
      file.mass_table = f.at("mass_table").get<std::vector<double>>();
      file.has_masses = f.at("has_masses").get<std::vector<bool>>();
      file.signed_ids = f.at("signed_ids").get<std::vector<bool>>();
      file.smoothing_dataset = f.at("smoothing_dataset").get<std::string>();
      files_.push_back(std::move(file));
    }
    for (const nlohmann::json& s : state.at("segments")) {
      segments_.push_back(Segment{s.at(0).get<std::size_t>(), s.at(1).get<int>(), s.at(2).get<std::uint64_t>()});
    }
    const nlohmann::json& h = state.at("header");
    header_.format = h.at("format").get<std::string>();
    header_.files = h.at("files").get<std::vector<std::string>>();
    header_.time = h.at("time").get<double>();
    header_.redshift = h.at("redshift").get<double>();
    header_.count_per_type = h.at("count_per_type").get<std::vector<std::uint64_t>>();
    header_.total_count = h.at("total_count").get<std::uint64_t>();
    header_.has_velocity = h.at("has_velocity").get<bool>();
    header_.has_id = h.at("has_id").get<bool>();
    header_.has_smoothing = h.at("has_smoothing").get<bool>();
    header_.cosmological = h.at("cosmological").get<bool>();
    header_.omega0 = h.at("omega0").get<double>();
    header_.omega_lambda = h.at("omega_lambda").get<double>();
    header_.hubble_param = h.at("hubble_param").get<double>();
    header_.extra = h.at("extra");
    smoothing_scale_ = state.at("smoothing_scale").get<double>();
    declared_box_ = state.at("declared_box").get<double>();
    // As FillHeader did in the walk, which it passed: sets the box and where it came from.
    SetBoxSize(files_.front().path, "BoxSize", declared_box_, options);
  }

  // Everything the walk found, for the constructor above.
  nlohmann::json State() const {
    nlohmann::json files = nlohmann::json::array();
    for (const Hdf5File& f : files_) {
      files.push_back({{"path", f.path},
                       {"this_file", f.this_file},
                       {"mass_table", f.mass_table},
                       {"has_masses", f.has_masses},
                       {"signed_ids", f.signed_ids},
                       {"smoothing_dataset", f.smoothing_dataset}});
    }
    nlohmann::json segments = nlohmann::json::array();
    for (const Segment& s : segments_) segments.push_back({s.file, s.type, s.count});
    const nlohmann::json header = {{"format", header_.format},
                                   {"files", header_.files},
                                   {"time", header_.time},
                                   {"redshift", header_.redshift},
                                   {"count_per_type", header_.count_per_type},
                                   {"total_count", header_.total_count},
                                   {"has_velocity", header_.has_velocity},
                                   {"has_id", header_.has_id},
                                   {"has_smoothing", header_.has_smoothing},
                                   {"cosmological", header_.cosmological},
                                   {"omega0", header_.omega0},
                                   {"omega_lambda", header_.omega_lambda},
                                   {"hubble_param", header_.hubble_param},
                                   {"extra", header_.extra}};
    return {{"files", files},
            {"segments", segments},
            {"header", header},
            {"smoothing_scale", smoothing_scale_},
            {"declared_box", declared_box_}};
  }

  // Reads the first and the last particle of every segment as Next() would:
  // each dataset read is opened, its hyperslab selected, and its first and
  // last chunk (when chunked) read through the filters. In the reader
  // process, at open, so that a dataset whose storage fails libhdf5 fails
  // before a long ingest begins.
  void Probe() {
    ParticleChunk chunk;
    for (const Segment& segment : segments_) {
      AppendRange(segment, 0, 1, chunk);
      if (segment.count > 1) AppendRange(segment, segment.count - 1, 1, chunk);
      chunk.clear();
    }
    CloseSegment();
  }

  // In the reader process: the range its owner asked for, as AppendRange,
  // with or without velocities and IDs as the owner's reader was asked.
  void ReadForOwner(const Segment& segment, std::uint64_t begin, std::size_t count, bool positions_only,
                    ParticleChunk& chunk) {
    if (segment.file >= files_.size() || segment.type < 0 ||
        static_cast<std::size_t>(segment.type) >= files_[segment.file].this_file.size()) {
      throw std::invalid_argument("a read of a segment the HDF5 reader does not have");
    }
    SetPositionsOnly(positions_only);
    AppendRange(segment, begin, count, chunk);
  }

 protected:
  void AppendRange(const Segment& segment, std::uint64_t begin, std::size_t count, ParticleChunk& chunk) override {
    if (reader_) {
      AppendRangeFromReader(segment, begin, count, chunk);
      return;
    }
    OpenSegment(segment);
    const std::size_t old = chunk.size();
    const std::string group = GroupName(segment.type);
    chunk.position.resize(3 * (old + count));
    ReadRows(coordinates_, group + "/Coordinates", H5T_NATIVE_DOUBLE, begin, count, 3,
             chunk.position.data() + 3 * old);
    if (FillsVelocity()) {
      chunk.velocity.resize(3 * (old + count));
      ReadRows(velocities_, group + "/Velocities", H5T_NATIVE_FLOAT, begin, count, 3,
               chunk.velocity.data() + 3 * old);
    }
    const Hdf5File& file = files_[segment.file];
    if (FillsId()) {
      chunk.id.resize(old + count);
      std::uint64_t* ids = chunk.id.data() + old;
      // Signed IDs are read as such, so that a negative one is seen (HDF5's
      // conversion to unsigned would make it 0), and then taken as they are.
      const bool is_signed = file.signed_ids[static_cast<std::size_t>(segment.type)];
      ReadRows(ids_, group + "/ParticleIDs", is_signed ? H5T_NATIVE_INT64 : H5T_NATIVE_UINT64, begin, count, 1, ids);
      if (is_signed) {
        for (std::size_t i = 0; i < count; ++i) {
          const auto id = static_cast<std::int64_t>(ids[i]);
          if (id < 0) {
            throw Error::BadInput(file.path, DescribeParticle(segment, begin + i) + " has a negative ID (" +
                                                 std::to_string(id) + ") in dataset /" + group +
                                                 "/ParticleIDs; IDs must be >= 0");
          }
        }
      }
    }
    if (header_.has_smoothing) {
      chunk.smoothing.resize(old + count);  // 0, not given, for the types without
      if (segment.type == 0) {
        float* h = chunk.smoothing.data() + old;
        ReadRows(smoothing_, group + "/" + file.smoothing_dataset, H5T_NATIVE_FLOAT, begin, count, 1, h);
        if (smoothing_scale_ != 1) {
          for (std::size_t i = 0; i < count; ++i) h[i] = static_cast<float>(h[i] * smoothing_scale_);
        }
      }
    }
    const auto t = static_cast<std::size_t>(segment.type);
    if (masses_.valid()) {
      chunk.mass.resize(old + count);
      ReadRows(masses_, group + "/Masses", H5T_NATIVE_DOUBLE, begin, count, 1, chunk.mass.data() + old);
    } else {
      chunk.mass.resize(old + count, file.mass_table[t]);
    }
    chunk.type.resize(old + count, static_cast<std::uint8_t>(segment.type));
  }

  void OnRewind() override { CloseSegment(); }

  std::string DescribeParticle(const Segment& segment, std::uint64_t index) const override {
    return GroupName(segment.type) + " particle " + std::to_string(index);
  }

  std::string DescribeSmoothing(const Segment& segment) const override {
    return "dataset /" + GroupName(segment.type) + "/" + files_[segment.file].smoothing_dataset;
  }

 private:
  static Handle RequireHeader(hid_t file, const std::string& path) {
    Handle header = OpenGroupIfPresent(file, "Header", path);
    if (!header.valid()) throw Error::BadInput(path, "missing group /Header: not a GADGET-style HDF5 snapshot");
    return header;
  }

  Hdf5File DescribeFile(const std::string& path, const std::vector<int>& types, bool& all_velocity,
                        bool& all_id) {
    Hdf5File description;
    description.path = path;
    const std::uint64_t file_bytes = BinaryFile(path).size();
    Handle file = OpenFile(path);
    Handle header = RequireHeader(file.get(), path);
    auto this_file = ReadCounts(header.get(), "NumPart_ThisFile", path, "/Header");
    if (!this_file || this_file->empty()) {
      throw Error::BadInput(path, "unreadable header: missing attribute /Header/NumPart_ThisFile");
    }
    if (this_file->size() > 256) {
      throw Error::BadInput(path, "/Header/NumPart_ThisFile has " + std::to_string(this_file->size()) +
                                      " entries; at most 256 particle types are supported");
    }
    description.this_file = *this_file;
    const std::size_t ntypes = this_file->size();
    description.mass_table.assign(ntypes, 0.0);
    if (auto table = ReadDoubles(header.get(), "MassTable", path, "/Header")) {
      for (std::size_t t = 0; t < std::min(ntypes, table->size()); ++t) description.mass_table[t] = (*table)[t];
    }
    description.has_masses.assign(ntypes, false);
    description.signed_ids.assign(ntypes, false);
    for (std::size_t t = 0; t < ntypes; ++t) {
      const std::uint64_t n = description.this_file[t];
      if (n == 0 || !IsTypeSelected(types, static_cast<int>(t))) continue;
      const double table_mass = description.mass_table[t];
      if (!(std::isfinite(table_mass) && table_mass >= 0)) {
        std::ostringstream value;
        value << table_mass;
        throw Error::BadInput(path, "attribute /Header/MassTable holds " + value.str() + " for the " +
                                        std::to_string(n) + " particles of type " + std::to_string(t) +
                                        "; it must be finite and > 0, or 0 for masses in a Masses dataset");
      }
      const std::string group = GroupName(static_cast<int>(t));
      if (!LinkExists(file.get(), group)) {
        throw Error::BadInput(path, "missing group /" + group + ": NumPart_ThisFile declares " + std::to_string(n) +
                                        " particles of type " + std::to_string(t));
      }
      if (!CheckDataset(file.get(), group + "/Coordinates", path, file_bytes, n, 3, false)) {
        throw Error::BadInput(path, "missing dataset /" + group + "/Coordinates for the " + std::to_string(n) +
                                        " particles NumPart_ThisFile declares");
      }
      if (read_velocity_) {
        all_velocity = CheckDataset(file.get(), group + "/Velocities", path, file_bytes, n, 3, false) && all_velocity;
      }
      if (read_id_) {
        bool is_signed = false;
        all_id = CheckDataset(file.get(), group + "/ParticleIDs", path, file_bytes, n, 1, true, &is_signed) && all_id;
        description.signed_ids[t] = is_signed;
      }
      description.has_masses[t] = CheckDataset(file.get(), group + "/Masses", path, file_bytes, n, 1, false);
      if (t == 0 && read_smoothing_) {
        for (const char* name : {"SmoothingLength", "SmoothingLengths"}) {
          if (CheckDataset(file.get(), group + "/" + name, path, file_bytes, n, 1, false)) {
            description.smoothing_dataset = name;
            break;
          }
        }
      }
      if (!description.has_masses[t] && description.mass_table[t] == 0) {
        throw Error::BadInput(path, "missing dataset /" + group + "/Masses, and MassTable[" + std::to_string(t) +
                                        "] is 0, so type " + std::to_string(t) + " has no masses");
      }
    }
    return description;
  }

  void FillHeader(const ReadOptions& options) {
    const std::string& path = files_.front().path;
    const std::size_t ntypes = files_.front().this_file.size();
    std::vector<std::uint64_t> file_sums(ntypes, 0);
    for (std::size_t f = 0; f < files_.size(); ++f) {
      for (std::size_t t = 0; t < ntypes; ++t) {
        const std::uint64_t n = files_[f].this_file[t];
        file_sums[t] += n;
        if (n > 0 && IsTypeSelected(options.types, static_cast<int>(t))) {
          segments_.push_back(Segment{f, static_cast<int>(t), n});
        }
      }
    }
    if (std::all_of(file_sums.begin(), file_sums.end(), [](std::uint64_t n) { return n == 0; })) {
      throw Error::BadInput(path, "empty input: no file of the snapshot holds any particles");
    }
    Handle file = OpenFile(path);
    Handle group = RequireHeader(file.get(), path);
    hid_t h = group.get();
    auto low = ReadCounts(h, "NumPart_Total", path, "/Header").value_or(std::vector<std::uint64_t>{});
    auto high = ReadCounts(h, "NumPart_Total_HighWord", path, "/Header").value_or(std::vector<std::uint64_t>{});
    ReconcileTypeTotals(path, low, high, file_sums, header_.extra);
    CountSegments(ntypes);

    Handle cosmology = OpenGroupIfPresent(file.get(), "Cosmology", path);
    Handle parameters = OpenGroupIfPresent(file.get(), "Parameters", path);
    const bool swift = cosmology.valid() || LinkExists(file.get(), "Code");
    header_.format = swift ? "hdf5-swift" : "hdf5-gadget";

    // Look a quantity up in /Header, then /Parameters (GADGET-4), then /Cosmology (SWIFT).
    auto lookup = [&](const char* header_name, const char* parameters_name,
                      const char* cosmology_name) -> std::optional<double> {
      if (auto v = ReadDoubles(h, header_name, path, "/Header"); v && !v->empty()) return v->front();
      if (parameters.valid() && parameters_name != nullptr) {
        if (auto v = ReadDoubles(parameters.get(), parameters_name, path, "/Parameters"); v && !v->empty()) {
          return v->front();
        }
      }
      if (cosmology.valid() && cosmology_name != nullptr) {
        if (auto v = ReadDoubles(cosmology.get(), cosmology_name, path, "/Cosmology"); v && !v->empty()) {
          return v->front();
        }
      }
      return std::nullopt;
    };
    // Every number is checked where it is taken; the field named is the
    // /Header one (or its first stand-in).
    auto finite = [&](const char* field, std::optional<double> value) -> std::optional<double> {
      if (value) RequireFinite(path, field, *value);
      return value;
    };
    header_.time = finite("Time", lookup("Time", nullptr, "Scale-factor")).value_or(0);
    header_.omega0 = finite("Omega0", lookup("Omega0", "Omega0", "Omega_m")).value_or(0);
    header_.omega_lambda = finite("OmegaLambda", lookup("OmegaLambda", "OmegaLambda", "Omega_lambda")).value_or(0);
    header_.hubble_param = finite("HubbleParam", lookup("HubbleParam", "HubbleParam", "h")).value_or(0);
    std::optional<double> redshift = finite("Redshift", lookup("Redshift", nullptr, "Redshift"));
    std::optional<double> comoving;
    if (parameters.valid()) comoving = FirstOr(ReadDoubles(parameters.get(), "ComovingIntegrationOn", path, "/Parameters"), -1);
    if (cosmology.valid()) comoving = FirstOr(ReadDoubles(cosmology.get(), "Cosmological run", path, "/Cosmology"), -1);
    if (comoving && *comoving >= 0) {
      header_.cosmological = *comoving > 0;
    } else {
      header_.cosmological = redshift.value_or(0) != 0 || header_.omega0 != 0;
    }
    if (swift && header_.cosmological) {
      // SWIFT's Header/Time is cosmic time; the manifest wants the scale factor.
      header_.time = finite("Scale-factor", lookup("Scale-factor", nullptr, "Scale-factor")).value_or(header_.time);
    }
    if (redshift) {
      header_.redshift = *redshift;
    } else if (header_.cosmological && header_.time > 0) {
      header_.redshift = RequireFinite(path, "Time (1/a - 1 as the redshift)", 1 / header_.time - 1);
    }

    // SWIFT writes BoxSize as a 3-vector; a cubic box is its one length, and
    // a non-cubic one keeps all three in extra with box_size the largest.
    double declared_box = 0;
    if (auto box = ReadDoubles(h, "BoxSize", path, "/Header"); box && !box->empty()) {
      // A NaN anywhere is the box's (std::max_element would pass it over).
      declared_box = *std::max_element(box->begin(), box->end());
      for (double length : *box) {
        if (!(std::isfinite(length) && length >= 0)) declared_box = length;
      }
      if (box->size() > 1 && std::isfinite(declared_box)) header_.extra["box_size_vector"] = *box;
    }
    declared_box_ = declared_box;
    SetBoxSize(path, "BoxSize", declared_box, options);

    header_.extra["mass_table"] = files_.front().mass_table;
    header_.extra["ntypes"] = ntypes;
    if (comoving) header_.extra["comoving_integration"] = *comoving;
    RecordUnits(file.get(), parameters, path);
  }

  // Smoothing lengths are read when every file that holds selected gas
  // (type 0) particles has them, as velocities are; SWIFT's only when its
  // kernel is known (SwiftKernelGamma).
  void FindSmoothing(const ReadOptions& options) {
    if (!options.read_smoothing || !IsTypeSelected(options.types, 0)) return;
    bool all_smoothing = true, any_smoothing = false;
    for (const Hdf5File& file : files_) {
      if (file.this_file.front() == 0) continue;
      all_smoothing = all_smoothing && !file.smoothing_dataset.empty();
      any_smoothing = any_smoothing || !file.smoothing_dataset.empty();
    }
    if (!any_smoothing) return;
    nlohmann::json& extra = header_.extra;
    if (!all_smoothing) {
      extra["smoothing_lengths_not_read"] = "a file with gas has no PartType0 smoothing lengths";
      return;
    }
    std::string name;  // as the first file with gas calls it
    for (auto file = files_.begin(); name.empty() && file != files_.end(); ++file) name = file->smoothing_dataset;
    if (header_.format == "hdf5-swift") {
      Handle file = OpenFile(files_.front().path);
      const std::optional<double> gamma = SwiftKernelGamma(file.get(), files_.front().path);
      if (!gamma) {
        extra["smoothing_lengths_not_read"] =
            "SWIFT's h is the kernel's support over a gamma that /HydroScheme's \"Kernel target N_ngb\" and "
            "\"Kernel eta\" give, and they are missing";
        return;
      }
      smoothing_scale_ = *gamma;
      extra["smoothing_lengths"] = "dataset /PartType0/" + name + " x kernel gamma " + std::to_string(*gamma);
    } else {
      extra["smoothing_lengths"] = "dataset /PartType0/" + name;
    }
    header_.has_smoothing = true;
  }

  // Keeps the unit attributes (GADGET-4 /Parameters Unit*, SWIFT /Units) so
  // that the manifest says what the numbers mean.
  void RecordUnits(hid_t file, const Handle& parameters, const std::string& path) {
    nlohmann::json units = nlohmann::json::object();
    if (parameters.valid()) {
      for (const char* name : {"UnitLength_in_cm", "UnitMass_in_g", "UnitVelocity_in_cm_per_s"}) {
        if (auto v = ReadDoubles(parameters.get(), name, path, "/Parameters"); v && !v->empty()) units[name] = v->front();
      }
    }
    Handle swift_units = OpenGroupIfPresent(file, "Units", path);
    if (swift_units.valid()) {
      H5Aiterate2(
          swift_units.get(), H5_INDEX_NAME, H5_ITER_NATIVE, nullptr,
          [](hid_t object, const char* name, const H5A_info_t*, void* data) -> herr_t {
            Handle attribute(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
            Handle type(H5Aget_type(attribute.get()), H5Tclose);
            H5T_class_t type_class = H5Tget_class(type.get());
            Handle space(H5Aget_space(attribute.get()), H5Sclose);
            double value = 0;
            if ((type_class == H5T_FLOAT || type_class == H5T_INTEGER) &&
                H5Sget_simple_extent_npoints(space.get()) == 1 &&
                H5Aread(attribute.get(), H5T_NATIVE_DOUBLE, &value) >= 0) {
              (*static_cast<nlohmann::json*>(data))[name] = value;
            }
            return 0;
          },
          &units);
      H5Eclear2(H5E_DEFAULT);
    }
    if (!units.empty()) header_.extra["units"] = units;
  }

  void OpenSegment(const Segment& segment) {
    if (open_file_index_ != segment.file || !file_.valid()) {
      CloseSegment();
      file_ = OpenFile(files_[segment.file].path);
      open_file_index_ = segment.file;
    }
    if (open_type_ == segment.type && coordinates_.valid()) return;
    coordinates_.Reset();
    velocities_.Reset();
    ids_.Reset();
    masses_.Reset();
    smoothing_.Reset();
    const std::string group = GroupName(segment.type);
    coordinates_ = OpenDataset(group + "/Coordinates");
    if (header_.has_velocity) velocities_ = OpenDataset(group + "/Velocities");
    if (header_.has_id) ids_ = OpenDataset(group + "/ParticleIDs");
    if (files_[segment.file].has_masses[static_cast<std::size_t>(segment.type)]) masses_ = OpenDataset(group + "/Masses");
    if (header_.has_smoothing && segment.type == 0) {
      smoothing_ = OpenDataset(group + "/" + files_[segment.file].smoothing_dataset);
    }
    open_type_ = segment.type;
  }

  void CloseSegment() {
    coordinates_.Reset();
    velocities_.Reset();
    ids_.Reset();
    masses_.Reset();
    smoothing_.Reset();
    file_.Reset();
    open_type_ = -1;
  }

  Handle OpenDataset(const std::string& name) {
    hid_t id = H5Dopen2(file_.get(), name.c_str(), H5P_DEFAULT);
    if (id < 0) ThrowHdf5(files_[open_file_index_].path, "cannot open dataset /" + name);
    return Handle(id, H5Dclose);
  }

  // Reads rows [begin, begin + count) of a (rows) or (rows, columns) dataset.
  void ReadRows(const Handle& dataset, const std::string& name, hid_t memory_type, std::uint64_t begin,
                std::size_t count, hsize_t columns, void* out) {
    const std::string& path = files_[open_file_index_].path;
    Handle file_space(H5Dget_space(dataset.get()), H5Sclose);
    int rank = H5Sget_simple_extent_ndims(file_space.get());
    hsize_t start[2] = {begin, 0};
    hsize_t extent[2] = {count, columns};
    if (rank < 1 || rank > 2 ||
        H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, extent, nullptr) < 0) {
      ThrowHdf5(path, "cannot select rows " + std::to_string(begin) + ".." + std::to_string(begin + count) +
                          " of dataset /" + name);
    }
    hsize_t memory_extent[1] = {count * columns};
    Handle memory_space(H5Screate_simple(1, memory_extent, nullptr), H5Sclose);
    if (H5Dread(dataset.get(), memory_type, memory_space.get(), file_space.get(), H5P_DEFAULT, out) < 0) {
      ThrowHdf5(path, "cannot read rows " + std::to_string(begin) + ".." + std::to_string(begin + count) +
                          " of dataset /" + name);
    }
  }

  // Particles [begin, begin + count) of `segment`, read by the reader
  // process (AnswerHdf5Request) and appended to `chunk` as AppendRange does.
  void AppendRangeFromReader(const Segment& segment, std::uint64_t begin, std::size_t count, ParticleChunk& chunk) {
    const std::string& path = files_[segment.file].path;
    const std::string request = RangeRequest(segment, begin, count, PositionsOnly());
    if (read_ahead_ != request) {
      if (!read_ahead_.empty()) reader_->Receive();  // not what was asked for after all
      reader_->Send(request);
    }
    read_ahead_.clear();
    const IsolatedResult result = reader_->Receive();
    // Reads come in order: the reader reads the next range of the segment
    // while this process works on this one.
    const std::uint64_t next = begin + count;
    if (result.returned && !result.bytes.empty() && result.bytes[0] == 'C' && next < segment.count) {
      const auto ahead = static_cast<std::size_t>(std::min<std::uint64_t>(count, segment.count - next));
      read_ahead_ = RangeRequest(segment, next, ahead, PositionsOnly());
      reader_->Send(read_ahead_);
    }
    const std::string rows =
        GroupName(segment.type) + " particles " + std::to_string(begin) + " to " + std::to_string(begin + count - 1);
    if (!result.returned) {
      throw Error::BadInput(path, "libhdf5 failed reading " + rows + ": the process reading them " + result.failure +
                                      "; the file is damaged");
    }
    std::string_view answer = result.bytes;
    if (!answer.empty() && answer[0] == 'E') ThrowAnswered(answer);
    const std::size_t old = chunk.size();
    const std::size_t bytes_per_particle = 3 * sizeof(double) + sizeof(double) +
                                           (FillsVelocity() ? 3 * sizeof(float) : 0) +
                                           (FillsId() ? sizeof(std::uint64_t) : 0) +
                                           (header_.has_smoothing ? sizeof(float) : 0);
    if (answer.size() != 1 + count * bytes_per_particle || answer[0] != 'C') {
      throw Error::BadInput(path, "the process reading " + rows + " with libhdf5 sent a malformed answer (" +
                                      std::to_string(answer.size()) + " bytes)");
    }
    answer.remove_prefix(1);
    auto take = [&](auto& column, std::size_t values) {
      using Value = typename std::decay_t<decltype(column)>::value_type;
      const std::size_t first = column.size();
      column.resize(first + values);
      std::memcpy(column.data() + first, answer.data(), values * sizeof(Value));
      answer.remove_prefix(values * sizeof(Value));
    };
    take(chunk.position, 3 * count);
    take(chunk.mass, count);
    if (FillsVelocity()) take(chunk.velocity, 3 * count);
    if (FillsId()) take(chunk.id, count);
    if (header_.has_smoothing) take(chunk.smoothing, count);
    chunk.type.resize(old + count, static_cast<std::uint8_t>(segment.type));
  }

  static std::string RangeRequest(const Segment& segment, std::uint64_t begin, std::size_t count,
                                  bool positions_only) {
    std::string request = "R";
    for (std::uint64_t value : {std::uint64_t{segment.file}, static_cast<std::uint64_t>(segment.type), begin,
                                std::uint64_t{count}, std::uint64_t{positions_only}}) {
      request.append(reinterpret_cast<const char*>(&value), sizeof value);
    }
    return request;
  }

  std::unique_ptr<IsolatedProcess> reader_;  // reads the particles when set (OpenHdf5Snapshot)
  std::string read_ahead_;                   // the range request sent to reader_ and not yet received
  std::vector<Hdf5File> files_;
  bool read_velocity_ = true, read_id_ = true, read_smoothing_ = true;
  double smoothing_scale_ = 1;  // what the file's smoothing lengths are multiplied by (SwiftKernelGamma)
  double declared_box_ = 0;     // the header's BoxSize (its largest side), before the options' say
  Handle file_, coordinates_, velocities_, ids_, masses_, smoothing_;
  std::size_t open_file_index_ = 0;
  int open_type_ = -1;
};

// libhdf5 parses a file's structure without guarding against damage: on a
// crafted or damaged file it can crash, read past its buffers, loop or ask
// for gigabytes (docs/TESTING.md). So every call into libhdf5 on a snapshot
// runs in a reader process of its own (isolated_process.h), started when
// the snapshot is opened and ended with its source. It walks the structure
// (the constructor above), reads the first and last value of each dataset
// (Probe) and hands back what it found (State, as CBOR) or the Error it
// threw; the owner builds its source from that without parsing the headers
// again, and then asks the reader for its particles a range at a time. A
// reader that dies, fails to allocate within its cap, or goes
// kReaderTimeLimit without opening another file (a structure that loops) or
// answering a read becomes an Error naming the file it was reading.
constexpr const char* kHdf5ReaderService = "hdf5-reader";
constexpr std::chrono::seconds kReaderTimeLimit{30};
// The reader's allocations: the walk needs little, a read of a range at
// most a chunk (kMaxChunkBytes) and its compressed bytes, and the range's
// particles (SegmentedSource reads at most 2^16 at a time).
constexpr std::uint64_t kReaderAddressSpace = std::uint64_t{1} << 30;

// Requests: 'O' and CBOR {file, options} opens a snapshot; 'R' and four
// native u64 (file index, type, first particle, count) reads a range.
// Answers: 'S' and the state as CBOR; 'C' and the range's columns
// (positions, masses, then velocities, IDs and smoothing lengths as the
// header has them), native bytes; or 'E', the error kind and its message.
std::string AnswerHdf5Request(std::string_view request) {
  static std::unique_ptr<Hdf5Source> source;
  try {
    if (!request.empty() && request[0] == 'O') {
      const nlohmann::json open = nlohmann::json::from_cbor(request.substr(1));
      const nlohmann::json& o = open.at("options");
      ReadOptions options;
      options.format = "hdf5";
      options.types = o.at("types").get<std::vector<int>>();
      options.chunk_particles = o.at("chunk_particles").get<std::size_t>();
      options.read_velocity = o.at("read_velocity").get<bool>();
      options.read_id = o.at("read_id").get<bool>();
      options.read_smoothing = o.at("read_smoothing").get<bool>();
      options.box_size_override = o.at("box_size_override").get<double>();
      options.ignore_box = o.at("ignore_box").get<bool>();
      source = std::make_unique<Hdf5Source>(open.at("file").get<std::string>(), options);
      source->Probe();
      const std::vector<std::uint8_t> cbor = nlohmann::json::to_cbor(source->State());
      return 'S' + std::string(cbor.begin(), cbor.end());
    }
    std::uint64_t values[5];  // file, type, first particle, count, positions only
    if (request.size() != 1 + sizeof values || request[0] != 'R' || !source) {
      throw std::invalid_argument("a request the HDF5 reader does not know");
    }
    std::memcpy(values, request.data() + 1, sizeof values);
    ParticleChunk chunk;
    source->ReadForOwner(Segment{values[0], static_cast<int>(values[1]), 0}, values[2],
                         static_cast<std::size_t>(values[3]), values[4] != 0, chunk);
    std::string answer = "C";
    answer.reserve(1 + chunk.position.size() * sizeof(double) + chunk.mass.size() * sizeof(double) +
                   chunk.velocity.size() * sizeof(float) + chunk.id.size() * sizeof(std::uint64_t) +
                   chunk.smoothing.size() * sizeof(float));
    auto put = [&](const auto& column) {
      answer.append(reinterpret_cast<const char*>(column.data()), column.size() * sizeof column[0]);
    };
    put(chunk.position);
    put(chunk.mass);
    put(chunk.velocity);
    put(chunk.id);
    put(chunk.smoothing);
    return answer;
  } catch (const Error& e) {
    return 'E' + std::string(1, static_cast<char>(e.kind())) + e.what();
  }
}

// A program that can open an HDF5 snapshot can be its reader: started as
// one, it serves here and exits before its main() runs.
[[maybe_unused]] const bool kServedAsReader = ServeIfStartedAs(kHdf5ReaderService, &AnswerHdf5Request);

// An 'E' answer: the Error the reader threw, thrown here as it was.
[[noreturn]] void ThrowAnswered(std::string_view answer) {
  if (answer.size() < 2) throw Error::BadInput("", "the HDF5 reader process sent an empty error");
  throw Error(static_cast<ErrorKind>(answer[1]), std::string(answer.substr(2)));
}

}  // namespace

bool IsHdf5Signature(const std::uint8_t bytes[8]) {
  static const std::uint8_t kSignature[8] = {0x89, 'H', 'D', 'F', '\r', '\n', 0x1a, '\n'};
  return std::memcmp(bytes, kSignature, 8) == 0;
}

std::unique_ptr<ParticleSource> OpenHdf5Snapshot(const std::string& file, const ReadOptions& options) {
  if (!options.isolate_hdf5) return std::make_unique<Hdf5Source>(file, options);
  auto reader =
      std::make_unique<IsolatedProcess>(kHdf5ReaderService, IsolationLimits{kReaderTimeLimit, kReaderAddressSpace});
  const nlohmann::json open = {{"file", file},
                               {"options",
                                {{"types", options.types},
                                 {"chunk_particles", options.chunk_particles},
                                 {"read_velocity", options.read_velocity},
                                 {"read_id", options.read_id},
                                 {"read_smoothing", options.read_smoothing},
                                 {"box_size_override", options.box_size_override},
                                 {"ignore_box", options.ignore_box}}}};
  const std::vector<std::uint8_t> cbor = nlohmann::json::to_cbor(open);
  const IsolatedResult result = reader->Call('O' + std::string(cbor.begin(), cbor.end()));
  if (!result.returned) {
    throw Error::BadInput(result.last_note.empty() ? file : result.last_note,
                          "libhdf5 failed reading this file's metadata: the process reading it " + result.failure +
                              "; the file is damaged, or not an HDF5 snapshot this reader understands");
  }
  const std::string& answer = result.bytes;
  if (!answer.empty() && answer[0] == 'E') ThrowAnswered(answer);
  if (answer.empty() || answer[0] != 'S') throw Error::BadInput(file, "the HDF5 reader process gave no answer");
  return std::make_unique<Hdf5Source>(nlohmann::json::from_cbor(answer.begin() + 1, answer.end()), options,
                                      std::move(reader));
}

}  // namespace octocosm
