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
        const auto& t = epoch.at("to_next");
        link = EpochLink{t.value("velocity_scale", 0.0), t.value("fit_residual", 1.0), t.value("max_displacement", 0.0)};
      }
      dataset.links_.push_back(link);
    }
    dataset.has_velocity_ = meta.value("has_velocity", false);
    dataset.has_displacement_ = meta.value("has_displacement", false);
    dataset.columns_ = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                       ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kType);
    const nlohmann::json& schema = dataset.store_.attribute_schema();
    if (schema.is_object() && schema.contains("columns")) {
      for (const auto& column : schema.at("columns")) {
        const int id = column.at("id").get<int>();
        if (id > 0 && id < 32) dataset.columns_ |= ColumnSet{1} << id;
      }
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

std::string Dataset::Where(std::uint32_t epoch, NodeKey key) const {
  return store_.epochs().at(epoch).file + " (epoch " + std::to_string(epoch) + ") block " + key.Path();
}

}  // namespace octocosm
