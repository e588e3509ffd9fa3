// The project's one portable random generator (initial conditions, cosmic
// web, scale-mode chunks): xoshiro256++ (Blackman & Vigna
// 2018) seeded through splitmix64, with deviates drawn without the
// trigonometry and logarithms that dominated the profile when they came from
// a Box-Muller generator (sincos alone was 37% of scale mode's run time):
// - Gaussian: the ziggurat method of Marsaglia & Tsang 2000 (J. Stat. Softw.
//   5(8)), 256 layers, in the double-precision form of Doornik 2005: one
//   64-bit draw, a table look-up and a comparison 98.8% of the time; a
//   wedge test with exp() or a tail draw with two log()s otherwise;
// - isotropic unit vector: Marsaglia 1972 (Ann. Math. Stat. 43, 645): for a
//   point (a, b) uniform in the unit disk with s = a^2 + b^2, the vector
//   (2a sqrt(1-s), 2b sqrt(1-s), 1-2s) is uniform on the sphere.
// Portable: the same seed gives the same numbers with any compiler and
// standard library (no std:: distributions; exp and log are only on the rare
// paths, and the tables are built with them once).
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

#include "base/hash.h"

namespace octocosm::synth {

class Random {
 public:
  explicit Random(std::uint64_t seed) {
    std::uint64_t x = seed;
    for (std::uint64_t& word : state_) word = SplitMix64(x);
  }

  // Uniform on [0, 1).
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }

  // Standard normal deviate.
  double Gaussian() {
    const ZigguratTables& z = Ziggurat();
    for (;;) {
      const std::uint64_t bits = Next();
      const int layer = static_cast<int>(bits & 0xff);
      const double u = 2.0 * (static_cast<double>(bits >> 11) * 0x1.0p-53) - 1.0;  // [-1, 1)
      const double x = u * z.x[layer];
      if (std::abs(x) < z.x[layer + 1]) return x;  // inside the layer's rectangle below the next one
      if (layer == 0) return Tail(u < 0.0);
      // In the wedge between the rectangle and the curve.
      if (z.f[layer + 1] + (z.f[layer] - z.f[layer + 1]) * Uniform() < std::exp(-0.5 * x * x)) return x;
    }
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
  static std::uint64_t Rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

  // xoshiro256++: every output bit is good, which the ziggurat needs (it
  // takes its layer from the low bits).
  std::uint64_t Next() {
    const std::uint64_t result = Rotl(state_[0] + state_[3], 23) + state_[0];
    const std::uint64_t t = state_[1] << 17;
    state_[2] ^= state_[0];
    state_[3] ^= state_[1];
    state_[1] ^= state_[2];
    state_[0] ^= state_[3];
    state_[2] ^= t;
    state_[3] = Rotl(state_[3], 45);
    return result;
  }

  // Layer i (1..255) is the rectangle [0, x[i]] x [f(x[i]), f(x[i+1])] under
  // f(x) = exp(-x^2 / 2); every layer, and the base (layer 0: the strip
  // below f(R) out to x[0] = V / f(R), standing for the strip plus the tail
  // beyond R), has area V. x[256] = 0, f[256] = 1.
  struct ZigguratTables {
    static constexpr double kR = 3.6541528853610088;     // start of the tail
    static constexpr double kV = 4.92867323399e-3;       // area of each layer
    double x[257];
    double f[257];
    ZigguratTables() {
      const double f_r = std::exp(-0.5 * kR * kR);
      x[0] = kV / f_r;
      x[1] = kR;
      for (int i = 2; i < 256; ++i) x[i] = std::sqrt(-2.0 * std::log(kV / x[i - 1] + std::exp(-0.5 * x[i - 1] * x[i - 1])));
      x[256] = 0.0;
      for (int i = 0; i < 257; ++i) f[i] = std::exp(-0.5 * x[i] * x[i]);
    }
  };
  static const ZigguratTables& Ziggurat() {
    static const ZigguratTables tables;
    return tables;
  }

  // Beyond R: Marsaglia 1964's tail method.
  double Tail(bool negative) {
    double x, y;
    do {
      x = std::log(1.0 - Uniform()) / ZigguratTables::kR;  // 1 - Uniform() is in (0, 1]
      y = std::log(1.0 - Uniform());
    } while (-2.0 * y < x * x);
    return negative ? x - ZigguratTables::kR : ZigguratTables::kR - x;
  }

  std::uint64_t state_[4];
};

}  // namespace octocosm::synth
