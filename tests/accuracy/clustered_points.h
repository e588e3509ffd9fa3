// Clustered test points for the accuracy suites: Gaussian halos of many sizes
// and richnesses on a uniform background, as float32 coordinates (what PCL
// holds, and what GADGET snapshots store), two particle species of mass 1 and
// 5 (as gas and dark matter, every third particle heavy), type 0 and 1, and
// IDs equal to the input index.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "index/cube.h"
#include "index/particle_chunk.h"

namespace octocosm::testing_support {

// A float32 value inside [lo, lo + size): the nearest float to x, clamped.
inline double FloatInside(double x, double lo, double size) {
  auto f = static_cast<float>(std::clamp(x, lo, lo + size));
  while (static_cast<double>(f) >= lo + size) f = std::nextafter(f, -INFINITY);
  while (static_cast<double>(f) < lo) f = std::nextafter(f, INFINITY);
  return f;
}

inline ParticleChunk ClusteredFloatPoints(std::size_t n, std::uint64_t seed, const Cube& cube,
                                          double halo_fraction = 0.7) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  struct Halo {
    double centre[3];
    double radius;
  };
  std::vector<Halo> halos(40);
  std::vector<double> richness(halos.size());
  for (std::size_t h = 0; h < halos.size(); ++h) {
    for (int a = 0; a < 3; ++a) halos[h].centre[a] = cube.origin[a] + cube.size * (0.1 + 0.8 * unit(rng));
    halos[h].radius = cube.size * 0.002 * std::exp2(5 * unit(rng));  // 0.2% to 6% of the cube
    richness[h] = std::exp2(6 * unit(rng));                            // members vary 64-fold
  }
  std::discrete_distribution<std::size_t> pick(richness.begin(), richness.end());
  std::normal_distribution<double> gauss(0, 1);
  ParticleChunk points;
  for (std::size_t i = 0; i < n; ++i) {
    const bool in_halo = unit(rng) < halo_fraction;
    const Halo& halo = halos[pick(rng)];
    for (int a = 0; a < 3; ++a) {
      const double x = in_halo ? halo.centre[a] + halo.radius * gauss(rng) : cube.origin[a] + cube.size * unit(rng);
      points.position.push_back(FloatInside(x, cube.origin[a], cube.size));
    }
    points.mass.push_back(i % 3 == 0 ? 5.0 : 1.0);
    points.type.push_back(i % 3 == 0 ? 1 : 0);
    points.id.push_back(i);
  }
  return points;
}

// Appends a point with the next ID.
inline void AddPoint(ParticleChunk& points, double x, double y, double z, double mass = 1.0) {
  points.position.insert(points.position.end(), {x, y, z});
  points.mass.push_back(mass);
  points.type.push_back(0);
  points.id.push_back(points.id.size());
}

}  // namespace octocosm::testing_support
