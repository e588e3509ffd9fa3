#include "index/dataset.h"

#include <filesystem>

#include "storage/error.h"

namespace octocosm {

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
      const auto& c = epoch.at("cube");
      Cube cube{c.at("origin").get<std::array<double, 3>>(), c.at("size").get<double>(), c.at("periodic").get<bool>()};
      cube.Validate();
      dataset.cubes_.push_back(cube);
      dataset.points_.push_back(epoch.at("points").get<std::uint64_t>());
      dataset.masses_.push_back(epoch.value("mass", 0.0));
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
