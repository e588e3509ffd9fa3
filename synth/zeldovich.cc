#include "synth/zeldovich.h"

#include <cmath>
#include <numbers>

#include "base/error.h"
#include "synth/fourier_grid.h"
#include "base/parallel_for.h"
#include "synth/random.h"

namespace octocosm::synth {

void ZeldovichDisplacement(int n, double box, const LinearPowerSpectrum& power, std::uint64_t seed, int threads,
                           std::span<double> displacement) {
  const std::size_t un = static_cast<std::size_t>(n);
  const std::size_t cells = un * un * un;
  if (displacement.size() != 3 * cells) {
    throw Error::InvalidArgument("ZeldovichDisplacement: output must hold 3 n^3 values");
  }

  FourierGrid density(n, threads);
  Random random(seed);
  for (std::size_t i = 0; i < un; ++i) {
    for (std::size_t j = 0; j < un; ++j) {
      for (std::size_t k = 0; k < un; ++k) density.Real(i, j, k) = random.Gaussian();
    }
  }
  density.Forward();

  // Unit white noise has <|W_k|^2> = n^3. The grid DFT of delta has
  // <|D_k|^2> = n^6 P / V, and the inverse transform carries a factor n^3.
  const double volume = box * box * box;
  const double cell_count = static_cast<double>(cells);
  const double fundamental = 2.0 * std::numbers::pi / box;
  ParallelFor(un, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      for (std::size_t j = 0; j < un; ++j) {
        for (std::size_t k = 0; k < density.complex_nz(); ++k) {
          std::complex<double>& mode = density.Mode(i, j, k);
          const double kx = fundamental * density.Frequency(i);
          const double ky = fundamental * density.Frequency(j);
          const double kz = fundamental * density.Frequency(k);
          const double k_length = std::sqrt(kx * kx + ky * ky + kz * kz);
          if (k_length == 0.0 || density.IsNyquist(i) || density.IsNyquist(j) || density.IsNyquist(k)) {
            mode = 0.0;
            continue;
          }
          mode *= std::sqrt(cell_count * power(k_length) / volume) / cell_count;
        }
      }
    }
  }, 1);

  FourierGrid component(n, threads);
  for (int d = 0; d < 3; ++d) {
    ParallelFor(un, threads, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        for (std::size_t j = 0; j < un; ++j) {
          for (std::size_t k = 0; k < density.complex_nz(); ++k) {
            const double kv[3] = {fundamental * density.Frequency(i), fundamental * density.Frequency(j),
                                  fundamental * density.Frequency(k)};
            const double k2 = kv[0] * kv[0] + kv[1] * kv[1] + kv[2] * kv[2];
            component.Mode(i, j, k) =
                k2 == 0.0 ? std::complex<double>(0.0) : std::complex<double>(0.0, kv[d] / k2) * density.Mode(i, j, k);
          }
        }
      }
    }, 1);
    component.Inverse();
    ParallelFor(un, threads, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        for (std::size_t j = 0; j < un; ++j) {
          for (std::size_t k = 0; k < un; ++k) displacement[3 * ((i * un + j) * un + k) + d] = component.Real(i, j, k);
        }
      }
    }, 1);
  }
}

}  // namespace octocosm::synth
