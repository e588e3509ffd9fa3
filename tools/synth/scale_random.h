// The random stream of one scale-mode chunk: xoshiro256+ (Blackman & Vigna
// 2018) seeded through splitmix64, with deviates drawn without trigonometry,
// which dominated the profile when taken from random.h's Box-Muller
// generator (sincos was 37% of the run time):
// - Gaussian: Marsaglia's polar method (Marsaglia & Bray 1964), two
//   deviates per accepted point of the unit disk (acceptance pi/4);
// - isotropic unit vector: Marsaglia 1972 (Ann. Math. Stat. 43, 645): for a
//   point (a, b) uniform in the unit disk with s = a^2 + b^2, the vector
//   (2a sqrt(1-s), 2b sqrt(1-s), 1-2s) is uniform on the sphere.
// Portable: the same seed gives the same numbers with any compiler and
// standard library (no std:: distributions).
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

namespace octocosm::synth {

class ScaleRandom {
 public:
  explicit ScaleRandom(std::uint64_t seed) {
    std::uint64_t x = seed;
    for (std::uint64_t& word : state_) word = SplitMix64(x);
  }

  // Uniform on [0, 1).
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }

  // Standard normal deviate.
  double Gaussian() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double a, b, s;
    do {
      a = 2.0 * Uniform() - 1.0;
      b = 2.0 * Uniform() - 1.0;
      s = a * a + b * b;
    } while (s >= 1.0 || s == 0.0);
    const double factor = std::sqrt(-2.0 * std::log(s) / s);
    spare_ = b * factor;
    has_spare_ = true;
    return a * factor;
  }

  // Uniform direction on the unit sphere.
  std::array<double, 3> Direction() {
    double a, b, s;
    do {
      a = 2.0 * Uniform() - 1.0;
      b = 2.0 * Uniform() - 1.0;
      s = a * a + b * b;
    } while (s >= 1.0);
    const double scale = 2.0 * std::sqrt(1.0 - s);
    return {a * scale, b * scale, 1.0 - 2.0 * s};
  }

 private:
  static std::uint64_t SplitMix64(std::uint64_t& x) {
    std::uint64_t z = (x += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  static std::uint64_t Rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

  // xoshiro256+: the fastest of the family; its weak low bits are dropped by
  // Uniform's shift.
  std::uint64_t Next() {
    const std::uint64_t result = state_[0] + state_[3];
    const std::uint64_t t = state_[1] << 17;
    state_[2] ^= state_[0];
    state_[3] ^= state_[1];
    state_[1] ^= state_[2];
    state_[0] ^= state_[3];
    state_[2] ^= t;
    state_[3] = Rotl(state_[3], 45);
    return result;
  }

  std::uint64_t state_[4];
  double spare_ = 0.0;
  bool has_spare_ = false;
};

}  // namespace octocosm::synth
