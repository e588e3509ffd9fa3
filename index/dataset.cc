#include "index/dataset.h"

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "storage/error.h"

namespace octocosm {
namespace {

// Headers record time and redshift apart, some in single precision: a scale
// factor this close (relative) to an epoch's is that epoch's.
constexpr double kSameScaleFactor = 1e-7;

// The scale factor that the ingest's record of an epoch's input header
// gives: its time in a cosmological run (tools/snapshot/snapshot_source.h),
// or 1 / (1 + z) where the time is missing.
std::optional<double> RecordedScaleFactor(const nlohmann::json& epoch) {
  const auto input = epoch.find("input");
  if (input == epoch.end() || !input->is_object() || !input->value("cosmological", false)) return std::nullopt;
  const auto number = [&](const char* name) -> std::optional<double> {
    const auto it = input->find(name);
    if (it == input->end() || !it->is_number() || !std::isfinite(it->get<double>())) return std::nullopt;
    return it->get<double>();
  };
  if (const std::optional<double> time = number("time"); time && *time > 0) return time;
  if (const std::optional<double> z = number("redshift"); z && *z > -1) return 1 / (1 + *z);
  return std::nullopt;
}

std::string Number(double x) {
  char text[32];
  std::snprintf(text, sizeof text, "%.9g", x);
  return text;
}

}  // namespace

double PhysicalTime::ScaleFactor() const {
  if (scale == Scale::kRedshift) {
    if (!(value > -1) || !std::isfinite(value)) throw Error::InvalidArgument(ToString() + ": a redshift must be finite and > -1");
    return 1 / (1 + value);
  }
  if (!(value > 0) || !std::isfinite(value)) throw Error::InvalidArgument(ToString() + ": a scale factor must be finite and > 0");
  return value;
}

std::string PhysicalTime::ToString() const {
  return (scale == Scale::kRedshift ? "redshift " : "scale factor ") + Number(value);
}

double FractionalEpochAt(const std::vector<std::optional<double>>& epoch_scale_factors, const PhysicalTime& time,
                         const std::string& store) {
  const double a = time.ScaleFactor();
  const std::vector<std::optional<double>>& recorded = epoch_scale_factors;
  if (recorded.empty()) throw Error::InvalidArgument(store + ": no epochs, so no " + time.ToString());
  for (std::size_t e = 0; e < recorded.size(); ++e) {
    if (!recorded[e]) {
      throw Error::InvalidArgument(store + ": epoch " + std::to_string(e) +
                                   " records no scale factor (its snapshot is not from a cosmological run), so " +
                                   time.ToString() + " cannot be placed among the epochs; give an epoch instead");
    }
  }
  // In the scale the caller used: redshift 1 / a - 1, or a.
  const auto in_scale = [&](std::size_t e) {
    return Number(time.scale == PhysicalTime::Scale::kRedshift ? 1 / *recorded[e] - 1 : *recorded[e]);
  };
  for (std::size_t e = 1; e < recorded.size(); ++e) {
    if (!(*recorded[e] > *recorded[e - 1])) {
      throw Error::InvalidArgument(store + ": the epochs' times do not increase strictly (epoch " + std::to_string(e - 1) +
                                   " at " + in_scale(e - 1) + ", epoch " + std::to_string(e) + " at " + in_scale(e) +
                                   "), so " + time.ToString() + " cannot be placed among them");
    }
  }
  for (std::size_t e = 0; e < recorded.size(); ++e) {
    if (std::fabs(a - *recorded[e]) <= kSameScaleFactor * *recorded[e]) return static_cast<double>(e);
  }
  const std::size_t last = recorded.size() - 1;
  if (!(a > *recorded.front() && a < *recorded.back())) {
    throw Error::InvalidArgument(store + ": " + time.ToString() + " is outside its epochs, which run from " +
                                 in_scale(0) + " (epoch 0) to " + in_scale(last) + " (epoch " + std::to_string(last) + ")");
  }
  // The last epoch at or before a: a lies strictly between it and the next.
  std::size_t e = 0;
  while (*recorded[e + 1] <= a) ++e;
  return static_cast<double>(e) + (a - *recorded[e]) / (*recorded[e + 1] - *recorded[e]);
}

double Dataset::FractionalEpochAt(const PhysicalTime& time) const {
  return octocosm::FractionalEpochAt(scale_factors_, time, store_.directory());
}

Dataset Dataset::Open(const std::string& directory) {
  Dataset dataset(StoreReader::Open(directory));
  const nlohmann::json& meta = dataset.store_.dataset();
  const std::string manifest = (std::filesystem::path(directory) / "manifest.json").string();
  try {
    dataset.capacity_ = meta.at("capacity").get<std::size_t>();
    dataset.max_level_ = meta.at("max_level").get<int>();
    if (meta.contains("sampler")) {
      const auto& sampler = meta.at("sampler");
      dataset.sampler_.alpha = sampler.value("alpha", dataset.sampler_.alpha);
      dataset.sampler_.density_grid_bits = sampler.value("density_grid_bits", dataset.sampler_.density_grid_bits);
      dataset.sampler_.seed = sampler.value("seed", dataset.sampler_.seed);
    }
    const auto& epochs = meta.at("epochs");
    if (epochs.size() != dataset.store_.epoch_count()) {
      throw Error::Corruption(manifest, "dataset metadata describes " + std::to_string(epochs.size()) +
                                            " epochs but the store has " + std::to_string(dataset.store_.epoch_count()));
    }
    for (const auto& epoch : epochs) {
      dataset.scale_factors_.push_back(RecordedScaleFactor(epoch));
      const auto& c = epoch.at("cube");
      Cube cube{c.at("origin").get<std::array<double, 3>>(), c.at("size").get<double>(), c.at("periodic").get<bool>()};
      cube.Validate();
      dataset.cubes_.push_back(cube);
      EpochSummary summary;
      summary.points = epoch.at("points").get<std::uint64_t>();
      if (epoch.contains("mass")) summary.mass = epoch.at("mass").get<double>();
      if (epoch.contains("nodes")) summary.nodes = epoch.at("nodes").get<std::uint64_t>();
      if (epoch.contains("leaves")) summary.leaves = epoch.at("leaves").get<std::uint64_t>();
      if (epoch.contains("depth")) summary.depth = epoch.at("depth").get<int>();
      dataset.summaries_.push_back(summary);
      std::optional<EpochLink> link;
      if (epoch.contains("to_next")) {
        const auto& to_next = epoch.at("to_next");
        link = EpochLink{to_next.at("velocity_scale").get<double>(), to_next.at("fit_residual").get<double>(),
                         to_next.at("least_squares_scale").get<double>(), to_next.at("inlier_fraction").get<double>(),
                         to_next.at("matched").get<std::uint64_t>(), to_next.value("max_excursion", 0.0)};
      }
      dataset.links_.push_back(link);
    }
    // Flags a store may lack (written before the column existed) mean "absent".
    const auto flag = [&](const char* name, ColumnId id) { return meta.value(name, false) ? ColumnBit(id) : 0; };
    dataset.every_epoch_columns_ = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                                   ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kType) |
                                   flag("has_velocity", ColumnId::kVelocity) | flag("has_id", ColumnId::kId);
    dataset.forward_columns_ =
        flag("has_displacement", ColumnId::kDisplacement) | flag("has_next_velocity", ColumnId::kNextVelocity);
    dataset.backward_columns_ =
        flag("has_prev_displacement", ColumnId::kPrevDisplacement) | flag("has_prev_velocity", ColumnId::kPrevVelocity);
    dataset.cluster_columns_ =
        flag("has_velocity_dispersion", ColumnId::kVelocityDispersion) | flag("has_shape", ColumnId::kShape);
    if ((dataset.cluster_columns_ & ColumnBit(ColumnId::kVelocityDispersion)) &&
        !(dataset.every_epoch_columns_ & ColumnBit(ColumnId::kVelocity))) {
      throw Error::Corruption(manifest, "dataset metadata declares velocity dispersions without velocities");
    }
    const std::string ids = meta.value("id_index", "");
    if (!ids.empty()) dataset.id_index_ = (std::filesystem::path(directory) / ids).string();
  } catch (const nlohmann::json::exception& e) {
    throw Error::Corruption(manifest, std::string("dataset metadata is not what octocosm ingest writes: ") + e.what());
  } catch (const Error& e) {
    if (e.kind() == ErrorKind::kInvalidArgument) throw Error::Corruption(manifest, e.what());
    throw;
  }
  if (dataset.max_level_ < 0 || dataset.max_level_ > kMaxLevel || dataset.capacity_ == 0) {
    throw Error::Corruption(manifest, "dataset metadata has an impossible capacity or depth limit");
  }
  return dataset;
}

ColumnSet Dataset::columns(std::uint32_t epoch) const {
  if (epoch >= epoch_count()) throw Error::InvalidArgument("epoch " + std::to_string(epoch) + " is not in the store");
  ColumnSet columns = every_epoch_columns_;
  if (epoch + 1 < epoch_count()) columns |= forward_columns_;
  if (epoch > 0) columns |= backward_columns_;
  return columns;
}

std::string Dataset::Where(std::uint32_t epoch, NodeKey key) const {
  return store_.epochs().at(epoch).file + " (epoch " + std::to_string(epoch) + ") block " + key.Path();
}

}  // namespace octocosm
