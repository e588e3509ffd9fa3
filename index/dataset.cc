#include "index/dataset.h"

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "base/error.h"

namespace octocosm {
namespace {

// Headers record time and redshift apart, some in single precision: a scale
// factor this close (relative) to an epoch's is that epoch's.
constexpr double kSameScaleFactor = 1e-7;

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
  const std::string manifest = (std::filesystem::path(directory) / "manifest.json").string();
  dataset.manifest_ = DatasetManifest::FromJson(dataset.store_.dataset(), manifest);
  const DatasetManifest& m = dataset.manifest_;
  if (m.epochs.size() != dataset.store_.epoch_count()) {
    throw Error::Corruption(manifest, "dataset metadata describes " + std::to_string(m.epochs.size()) +
                                          " epochs but the store has " + std::to_string(dataset.store_.epoch_count()));
  }
  for (const EpochRecord& epoch : m.epochs) dataset.scale_factors_.push_back(epoch.ScaleFactor());
  const auto flag = [](bool set, ColumnId id) { return set ? ColumnBit(id) : 0; };
  dataset.every_epoch_columns_ = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                                 ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kType) |
                                 flag(m.has_velocity, ColumnId::kVelocity) | flag(m.has_id, ColumnId::kId);
  dataset.forward_columns_ =
      flag(m.has_displacement, ColumnId::kDisplacement) | flag(m.has_next_velocity, ColumnId::kNextVelocity);
  dataset.backward_columns_ =
      flag(m.has_prev_displacement, ColumnId::kPrevDisplacement) | flag(m.has_prev_velocity, ColumnId::kPrevVelocity);
  dataset.cluster_columns_ =
      flag(m.has_velocity_dispersion, ColumnId::kVelocityDispersion) | flag(m.has_shape, ColumnId::kShape) |
      (m.has_cluster_links ? kClusterLinkColumns : 0);
  if (!m.id_index.empty()) dataset.id_index_ = (std::filesystem::path(directory) / m.id_index).string();
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
  return store_.directory() + "/" + store_.epochs().at(epoch).file + " (epoch " + std::to_string(epoch) + ") block " + key.Path();
}

}  // namespace octocosm
