#include "synth/cosmic_web.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>
#include <utility>

#include "synth/random.h"

namespace octocosm::synth {
namespace {

using Vec3 = std::array<double, 3>;

constexpr int kNeighboursPerNode = 3;
// Mixed into the seed so the web's stream differs from every chunk's.
constexpr std::uint64_t kWebStream = 0x5eed'0f'c05'31cULL;

double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
Vec3 Normalized(const Vec3& v) {
  const double length = std::sqrt(Dot(v, v));
  return {v[0] / length, v[1] / length, v[2] / length};
}

// For points inside the box, where each difference is below one box length,
// two selects replace the division and rounding, and branches that random
// points would mispredict half the time (the nearest-neighbour search makes
// nodes^2 of these).
Vec3 MinimalImage(const Vec3& from, const Vec3& to, double box) {
  Vec3 d;
  for (int k = 0; k < 3; ++k) {
    const double difference = to[k] - from[k];
    d[k] = difference - (difference > 0.5 * box ? box : 0.0) + (difference < -0.5 * box ? box : 0.0);
  }
  return d;
}

double Wrap(double x, double box) {
  x -= box * std::floor(x / box);
  return x < box ? x : 0.0;  // x a hair below 0 can round up to box
}

// first[i] for shares of `total` proportional to weights, by cumulative
// rounding so they add up to `total` exactly; first has weights.size() + 1
// entries, the last equal to total.
std::vector<std::uint64_t> ShareOut(std::uint64_t total, const std::vector<double>& weights) {
  const double sum = std::accumulate(weights.begin(), weights.end(), 0.0);
  std::vector<std::uint64_t> first(weights.size() + 1, 0);
  double cumulative = 0.0;
  for (std::size_t i = 0; i < weights.size(); ++i) {
    first[i] = sum > 0.0 ? std::min<std::uint64_t>(total, static_cast<std::uint64_t>(static_cast<double>(total) * (cumulative / sum)))
                         : total * i / weights.size();
    if (i > 0) first[i] = std::max(first[i], first[i - 1]);
    cumulative += weights[i];
  }
  first[weights.size()] = total;
  return first;
}

// Draws from p(x) ~ x^-slope on [1, range] by inverse transform.
double PowerLawDeviate(double u, double slope, double range) {
  if (range <= 1.0) return 1.0;
  if (std::abs(slope - 1.0) < 1e-9) return std::pow(range, u);
  const double e = 1.0 - slope;
  return std::pow(1.0 + u * (std::pow(range, e) - 1.0), 1.0 / e);
}

}  // namespace

CosmicWeb BuildCosmicWeb(const ScaleOptions& options) {
  CosmicWeb web;
  const double box = options.box_size_mpc_h;
  const std::uint64_t n = options.particle_count;
  web.box_size = box;
  web.filament_radius = options.filament_radius_mpc_h;
  web.particle_mass = options.omega_matter * kCriticalDensity * box * box * box / static_cast<double>(n);
  web.halo_particles = std::min<std::uint64_t>(n, static_cast<std::uint64_t>(std::llround(static_cast<double>(n) * options.halo_fraction)));
  web.filament_particles = std::min<std::uint64_t>(
      n - web.halo_particles, static_cast<std::uint64_t>(std::llround(static_cast<double>(n) * options.filament_fraction)));
  web.background_particles = n - web.halo_particles - web.filament_particles;

  Random random(options.seed ^ kWebStream);
  auto uniform = [&random] { return random.Uniform(); };  // [0, 1)

  // Skeleton.
  const std::size_t halo_count =
      web.halo_particles == 0 ? 0 : (options.halo_count > 0 ? options.halo_count : DefaultHaloCount(web.halo_particles));
  const std::size_t node_count = options.node_count > 0 ? options.node_count : DefaultNodeCount(halo_count);
  web.nodes.resize(node_count);
  for (Vec3& node : web.nodes) {
    for (double& x : node) x = Wrap(uniform() * box, box);
  }
  std::vector<std::pair<std::size_t, std::size_t>> edges;
  for (std::size_t i = 0; i < node_count; ++i) {
    // The nearest kNeighboursPerNode, kept sorted by (distance, index).
    std::array<std::pair<double, std::size_t>, kNeighboursPerNode> nearest;
    nearest.fill({INFINITY, node_count});
    for (std::size_t j = 0; j < node_count; ++j) {
      if (j == i) continue;
      const Vec3 d = MinimalImage(web.nodes[i], web.nodes[j], box);
      std::pair<double, std::size_t> candidate{Dot(d, d), j};
      if (!(candidate < nearest.back())) continue;
      nearest.back() = candidate;
      for (std::size_t k = nearest.size() - 1; k > 0 && nearest[k] < nearest[k - 1]; --k) std::swap(nearest[k], nearest[k - 1]);
    }
    for (const auto& [distance, j] : nearest) {
      if (j < node_count) edges.emplace_back(std::min(i, j), std::max(i, j));
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());

  std::vector<double> lengths;
  for (const auto& [a, b] : edges) {
    ScaleFilament filament;
    filament.start = web.nodes[a];
    filament.axis = MinimalImage(web.nodes[a], web.nodes[b], box);
    const double length = std::sqrt(Dot(filament.axis, filament.axis));
    if (length > 0.0) {
      const Vec3 direction = Normalized(filament.axis);
      // Any vector not parallel to the axis gives a normal: take the
      // coordinate axis along which the direction is smallest.
      Vec3 helper{0.0, 0.0, 0.0};
      int smallest = 0;
      for (int k = 1; k < 3; ++k) {
        if (std::abs(direction[k]) < std::abs(direction[smallest])) smallest = k;
      }
      helper[smallest] = 1.0;
      filament.normal1 = Normalized(Cross(direction, helper));
      filament.normal2 = Cross(direction, filament.normal1);
    } else {
      filament.normal1 = {1.0, 0.0, 0.0};
      filament.normal2 = {0.0, 1.0, 0.0};
    }
    lengths.push_back(length);
    web.filaments.push_back(filament);
  }
  const std::vector<std::uint64_t> filament_first = ShareOut(web.filament_particles, lengths);
  for (std::size_t f = 0; f < web.filaments.size(); ++f) {
    web.filaments[f].first = web.halo_particles + filament_first[f];
    web.filaments[f].count = filament_first[f + 1] - filament_first[f];
  }
  std::vector<double> length_cdf(lengths.size());
  std::partial_sum(lengths.begin(), lengths.end(), length_cdf.begin());

  // Halo masses and particle shares.
  std::vector<double> relative_mass(halo_count);
  for (double& m : relative_mass) m = PowerLawDeviate(uniform(), options.mass_function_slope, options.halo_mass_range);
  const std::vector<std::uint64_t> halo_first = ShareOut(web.halo_particles, relative_mass);
  web.halos.resize(halo_count);
  const double mean_density = options.omega_matter * kCriticalDensity;
  for (std::size_t h = 0; h < halo_count; ++h) {
    ScaleHalo& halo = web.halos[h];
    halo.first = halo_first[h];
    halo.count = halo_first[h + 1] - halo_first[h];
    const double mass = static_cast<double>(halo.count) * web.particle_mass;  // 1e10 Msun/h
    halo.r200 = std::cbrt(3.0 * mass / (4.0 * std::numbers::pi * 200.0 * mean_density));
    if (halo.count > 0) {
      const double v200 = std::sqrt(kGravitationalConstant * mass * 1e10 / halo.r200);
      halo.velocity_dispersion = static_cast<float>(v200 / std::numbers::sqrt2);
      halo.concentration_index = web.nfw.NearestIndex(DuffyConcentration(mass * 1e10));
    }
    for (float& v : halo.bulk_velocity) v = static_cast<float>(kHaloBulkVelocityDispersion * random.Gaussian());
  }

  // Placement: the heaviest halos on the nodes, the others along filaments.
  std::vector<std::size_t> by_mass(halo_count);
  std::iota(by_mass.begin(), by_mass.end(), std::size_t{0});
  std::stable_sort(by_mass.begin(), by_mass.end(),
                   [&](std::size_t a, std::size_t b) { return relative_mass[a] > relative_mass[b]; });
  for (std::size_t rank = 0; rank < halo_count; ++rank) {
    ScaleHalo& halo = web.halos[by_mass[rank]];
    if (rank < node_count || web.filaments.empty() || length_cdf.back() <= 0.0) {
      halo.center = rank < node_count ? web.nodes[rank] : Vec3{uniform() * box, uniform() * box, uniform() * box};
    } else {
      const double pick = uniform() * length_cdf.back();
      const std::size_t f = std::min<std::size_t>(
          web.filaments.size() - 1,
          static_cast<std::size_t>(std::upper_bound(length_cdf.begin(), length_cdf.end(), pick) - length_cdf.begin()));
      const ScaleFilament& filament = web.filaments[f];
      const double t = uniform();
      for (int k = 0; k < 3; ++k) {
        halo.center[k] = filament.start[k] + t * filament.axis[k] + web.filament_radius * random.Gaussian();
      }
    }
    for (double& x : halo.center) x = Wrap(x, box);
  }
  return web;
}

}  // namespace octocosm::synth
