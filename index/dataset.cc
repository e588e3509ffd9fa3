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
