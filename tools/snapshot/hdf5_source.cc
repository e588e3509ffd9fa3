#include "tools/snapshot/hdf5_source.h"

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <optional>
#include <utility>
#include <vector>

#include "storage/error.h"
#include "tools/snapshot/file_set.h"
#include "tools/snapshot/segmented_source.h"

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

std::optional<std::vector<std::uint64_t>> ReadCounts(hid_t object, const char* name, const std::string& path,
                                                     const std::string& group) {
  return ReadAttribute<std::uint64_t>(object, name, H5T_NATIVE_UINT64, path, group);
}

// First element of an optional attribute; `fallback` when absent or empty.
double FirstOr(const std::optional<std::vector<double>>& values, double fallback) {
  return values && !values->empty() ? values->front() : fallback;
}

// Shape and element class of one dataset, checked against what we expect.
struct DatasetShape {
  bool present = false;
  int rank = 0;
  hsize_t rows = 0, columns = 1;
};

DatasetShape InspectDataset(hid_t file, const std::string& name, const std::string& path, bool integer_only) {
  DatasetShape shape;
  if (!LinkExists(file, name)) return shape;
  Handle dataset(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!dataset.valid()) ThrowHdf5(path, "cannot open dataset /" + name);
  Handle type(H5Dget_type(dataset.get()), H5Tclose);
  H5T_class_t type_class = H5Tget_class(type.get());
  if (type_class != H5T_INTEGER && (integer_only || type_class != H5T_FLOAT)) {
    throw Error::BadInput(path, "dataset /" + name + " has element class " + std::to_string(type_class) +
                                    "; expected " + (integer_only ? "integers" : "numbers"));
  }
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
  return shape;
}

// Checks that dataset `name` has `rows` x `columns` values; false when absent.
bool CheckDataset(hid_t file, const std::string& name, const std::string& path, std::uint64_t rows,
                  hsize_t columns, bool integer_only) {
  DatasetShape shape = InspectDataset(file, name, path, integer_only);
  if (!shape.present) return false;
  if (shape.rows != rows || shape.columns != columns) {
    throw Error::BadInput(path, "counts do not add up: dataset /" + name + " has " + std::to_string(shape.rows) +
                                    " x " + std::to_string(shape.columns) + " values; the header's NumPart_ThisFile "
                                    "declares " + std::to_string(rows) + " particles, so expected " +
                                    std::to_string(rows) + " x " + std::to_string(columns));
  }
  return true;
}

struct Hdf5File {
  std::string path;
  std::vector<std::uint64_t> this_file;  // NumPart_ThisFile
  std::vector<double> mass_table;        // MassTable, zeros when absent
  std::vector<bool> has_masses;          // per type: a Masses dataset is present
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

class Hdf5Source final : public SegmentedSource {
 public:
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

 protected:
  void AppendRange(const Segment& segment, std::uint64_t begin, std::size_t count, ParticleChunk& chunk) override {
    OpenSegment(segment);
    const std::size_t old = chunk.size();
    const std::string group = GroupName(segment.type);
    chunk.position.resize(3 * (old + count));
    ReadRows(coordinates_, group + "/Coordinates", H5T_NATIVE_DOUBLE, begin, count, 3,
             chunk.position.data() + 3 * old);
    if (header_.has_velocity) {
      chunk.velocity.resize(3 * (old + count));
      ReadRows(velocities_, group + "/Velocities", H5T_NATIVE_FLOAT, begin, count, 3,
               chunk.velocity.data() + 3 * old);
    }
    if (header_.has_id) {
      chunk.id.resize(old + count);
      ReadRows(ids_, group + "/ParticleIDs", H5T_NATIVE_UINT64, begin, count, 1, chunk.id.data() + old);
    }
    const Hdf5File& file = files_[segment.file];
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
    for (std::size_t t = 0; t < ntypes; ++t) {
      const std::uint64_t n = description.this_file[t];
      if (n == 0 || !IsTypeSelected(types, static_cast<int>(t))) continue;
      const std::string group = GroupName(static_cast<int>(t));
      if (!LinkExists(file.get(), group)) {
        throw Error::BadInput(path, "missing group /" + group + ": NumPart_ThisFile declares " + std::to_string(n) +
                                        " particles of type " + std::to_string(t));
      }
      if (!CheckDataset(file.get(), group + "/Coordinates", path, n, 3, false)) {
        throw Error::BadInput(path, "missing dataset /" + group + "/Coordinates for the " + std::to_string(n) +
                                        " particles NumPart_ThisFile declares");
      }
      if (read_velocity_) all_velocity = CheckDataset(file.get(), group + "/Velocities", path, n, 3, false) && all_velocity;
      if (read_id_) all_id = CheckDataset(file.get(), group + "/ParticleIDs", path, n, 1, true) && all_id;
      description.has_masses[t] = CheckDataset(file.get(), group + "/Masses", path, n, 1, false);
      if (t == 0 && read_smoothing_) {
        for (const char* name : {"SmoothingLength", "SmoothingLengths"}) {
          if (CheckDataset(file.get(), group + "/" + name, path, n, 1, false)) {
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
    header_.time = lookup("Time", nullptr, "Scale-factor").value_or(0);
    header_.omega0 = lookup("Omega0", "Omega0", "Omega_m").value_or(0);
    header_.omega_lambda = lookup("OmegaLambda", "OmegaLambda", "Omega_lambda").value_or(0);
    header_.hubble_param = lookup("HubbleParam", "HubbleParam", "h").value_or(0);
    std::optional<double> redshift = lookup("Redshift", nullptr, "Redshift");
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
      header_.time = lookup("Scale-factor", nullptr, "Scale-factor").value_or(header_.time);
    }
    if (redshift) {
      header_.redshift = *redshift;
    } else if (header_.cosmological && header_.time > 0) {
      header_.redshift = 1 / header_.time - 1;
    }

    // SWIFT writes BoxSize as a 3-vector; a cubic box is its one length, and
    // a non-cubic one keeps all three in extra with box_size the largest.
    if (auto box = ReadDoubles(h, "BoxSize", path, "/Header"); box && !box->empty()) {
      header_.box_size = *std::max_element(box->begin(), box->end());
      if (box->size() > 1) header_.extra["box_size_vector"] = *box;
    }
    if (options.box_size_override >= 0) header_.box_size = options.box_size_override;

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

  std::vector<Hdf5File> files_;
  bool read_velocity_ = true, read_id_ = true, read_smoothing_ = true;
  double smoothing_scale_ = 1;  // what the file's smoothing lengths are multiplied by (SwiftKernelGamma)
  Handle file_, coordinates_, velocities_, ids_, masses_, smoothing_;
  std::size_t open_file_index_ = 0;
  int open_type_ = -1;
};

}  // namespace

bool IsHdf5Signature(const std::uint8_t bytes[8]) {
  static const std::uint8_t kSignature[8] = {0x89, 'H', 'D', 'F', '\r', '\n', 0x1a, '\n'};
  return std::memcmp(bytes, kSignature, 8) == 0;
}

std::unique_ptr<ParticleSource> OpenHdf5Snapshot(const std::string& file, const ReadOptions& options) {
  return std::make_unique<Hdf5Source>(file, options);
}

}  // namespace octocosm
