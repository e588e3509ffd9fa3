#include "index/dataset_manifest.h"

#include <cmath>

#include "base/error.h"

namespace octocosm {

std::optional<double> EpochRecord::ScaleFactor() const {
  if (!input.is_object() || !input.value("cosmological", false)) return std::nullopt;
  const auto number = [&](const char* name) -> std::optional<double> {
    const auto it = input.find(name);
    if (it == input.end() || !it->is_number() || !std::isfinite(it->get<double>())) return std::nullopt;
    return it->get<double>();
  };
  if (const std::optional<double> time = number("time"); time && *time > 0) return time;
  if (const std::optional<double> z = number("redshift"); z && *z > -1) return 1 / (1 + *z);
  return std::nullopt;
}

nlohmann::json EpochRecord::ToJson(std::size_t epoch_number) const {
  const EpochRecord& r = *this;
  nlohmann::json epoch = {{"epoch", epoch_number},
                          {"input", r.input},
                          {"cube", {{"origin", r.cube.origin}, {"size", r.cube.size}, {"periodic", r.cube.periodic}}},
                          {"points", r.summary.points},
                          {"missing_in_next", r.missing_in_next},
                          {"missing_in_prev", r.missing_in_prev},
                          {"duplicate_ids", r.duplicate_ids}};
  if (r.summary.mass) epoch["mass"] = *r.summary.mass;
  if (r.summary.nodes) epoch["nodes"] = *r.summary.nodes;
  if (r.summary.leaves) epoch["leaves"] = *r.summary.leaves;
  if (r.summary.depth) epoch["depth"] = *r.summary.depth;
  if (r.to_next) {
    const EpochLink& link = *r.to_next;
    epoch["to_next"] = {{"velocity_scale", link.velocity_scale},
                        {"fit_residual", link.fit_residual},
                        {"least_squares_scale", link.least_squares_scale},
                        {"inlier_fraction", link.inlier_fraction},
                        {"matched", link.matched},
                        {"max_excursion", link.max_excursion}};
  }
  return epoch;
}

nlohmann::json DatasetManifest::ToJson() const {
  nlohmann::json epoch_list = nlohmann::json::array();
  for (std::size_t e = 0; e < epochs.size(); ++e) epoch_list.push_back(epochs[e].ToJson(e));
  return {{"generator", generator},
          {"capacity", capacity},
          {"max_level", max_level},
          {"coarse", coarse},
          {"smoothing", {{"rule", smoothing_rule}, {"neighbours", neighbours}}},
          {"sampler", {{"alpha", sampler.alpha}, {"density_grid_bits", sampler.density_grid_bits}, {"seed", sampler.seed}}},
          {"has_velocity", has_velocity},
          {"has_id", has_id},
          {"has_displacement", has_displacement},
          {"has_next_velocity", has_next_velocity},
          {"has_prev_displacement", has_prev_displacement},
          {"has_prev_velocity", has_prev_velocity},
          {"has_velocity_dispersion", has_velocity_dispersion},
          {"has_shape", has_shape},
          {"has_cluster_links", has_cluster_links},
          {"id_index", id_index},
          {"epochs", std::move(epoch_list)}};
}

EpochRecord EpochRecord::FromJson(const nlohmann::json& epoch) {
  EpochRecord r;
  const auto& c = epoch.at("cube");
  r.cube = Cube{c.at("origin").get<std::array<double, 3>>(), c.at("size").get<double>(), c.at("periodic").get<bool>()};
  r.cube.Validate();
  r.summary.points = epoch.at("points").get<std::uint64_t>();
  if (epoch.contains("mass")) r.summary.mass = epoch.at("mass").get<double>();
  if (epoch.contains("nodes")) r.summary.nodes = epoch.at("nodes").get<std::uint64_t>();
  if (epoch.contains("leaves")) r.summary.leaves = epoch.at("leaves").get<std::uint64_t>();
  if (epoch.contains("depth")) r.summary.depth = epoch.at("depth").get<int>();
  r.missing_in_next = epoch.value("missing_in_next", std::uint64_t{0});
  r.missing_in_prev = epoch.value("missing_in_prev", std::uint64_t{0});
  r.duplicate_ids = epoch.value("duplicate_ids", std::uint64_t{0});
  if (epoch.contains("to_next")) {
    const auto& to_next = epoch.at("to_next");
    r.to_next = EpochLink{to_next.at("velocity_scale").get<double>(), to_next.at("fit_residual").get<double>(),
                          to_next.at("least_squares_scale").get<double>(), to_next.at("inlier_fraction").get<double>(),
                          to_next.at("matched").get<std::uint64_t>(), to_next.value("max_excursion", 0.0)};
  }
  if (epoch.contains("input")) r.input = epoch.at("input");
  return r;
}

DatasetManifest DatasetManifest::FromJson(const nlohmann::json& json, const std::string& path) {
  DatasetManifest m;
  try {
    m.generator = json.value("generator", std::string());
    m.capacity = json.at("capacity").get<std::size_t>();
    m.max_level = json.at("max_level").get<int>();
    m.coarse = json.value("coarse", std::string("sample"));
    if (json.contains("smoothing")) {
      const auto& smoothing = json.at("smoothing");
      m.smoothing_rule = smoothing.value("rule", m.smoothing_rule);
      m.neighbours = smoothing.value("neighbours", m.neighbours);
    }
    if (json.contains("sampler")) {
      const auto& sampler = json.at("sampler");
      m.sampler.alpha = sampler.value("alpha", m.sampler.alpha);
      m.sampler.density_grid_bits = sampler.value("density_grid_bits", m.sampler.density_grid_bits);
      m.sampler.seed = sampler.value("seed", m.sampler.seed);
    }
    // Flags a store may lack (written before the column existed) mean "absent".
    m.has_velocity = json.value("has_velocity", false);
    m.has_id = json.value("has_id", false);
    m.has_displacement = json.value("has_displacement", false);
    m.has_next_velocity = json.value("has_next_velocity", false);
    m.has_prev_displacement = json.value("has_prev_displacement", false);
    m.has_prev_velocity = json.value("has_prev_velocity", false);
    m.has_velocity_dispersion = json.value("has_velocity_dispersion", false);
    m.has_shape = json.value("has_shape", false);
    m.has_cluster_links = json.value("has_cluster_links", false);
    m.id_index = json.value("id_index", std::string());
    for (const auto& epoch : json.at("epochs")) m.epochs.push_back(EpochRecord::FromJson(epoch));
  } catch (const nlohmann::json::exception& e) {
    throw Error::Corruption(path, std::string("dataset metadata is not what octocosm ingest writes: ") + e.what());
  } catch (const Error& e) {
    if (e.kind() == ErrorKind::kInvalidArgument) throw Error::Corruption(path, e.what());
    throw;
  }
  if (m.max_level < 0 || m.max_level > kMaxLevel || m.capacity == 0) {
    throw Error::Corruption(path, "dataset metadata has an impossible capacity or depth limit");
  }
  if (m.has_velocity_dispersion && !m.has_velocity) {
    throw Error::Corruption(path, "dataset metadata declares velocity dispersions without velocities");
  }
  return m;
}

}  // namespace octocosm
