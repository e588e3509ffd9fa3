#include "synth/power_spectrum_estimator.h"

#include <cmath>
#include <numbers>

#include "base/error.h"
#include "synth/cloud_in_cell.h"
#include "synth/fourier_grid.h"

namespace octocosm::synth {

std::vector<PowerSpectrumBin> MeasurePowerSpectrum(std::span<const double> positions, double box, int grid_n,
                                                   int threads) {
  if (positions.empty() || positions.size() % 3 != 0) {
    throw Error::InvalidArgument("MeasurePowerSpectrum needs a non-empty list of x,y,z positions");
  }
  if (!(box > 0.0)) throw Error::InvalidArgument("MeasurePowerSpectrum: box size must be positive");
  FourierGrid grid(grid_n, threads);
  const std::size_t count = positions.size() / 3;
  const double n = grid_n;
  DepositCic(positions, box, n * n * n / static_cast<double>(count), grid);
  grid.Forward();

  // The grid holds 1 + delta per cell; its DFT D_k relates to the continuous
  // transform by delta_k = D_k V / n^3, and P = |delta_k|^2 / V.
  const double volume = box * box * box;
  const double to_power = volume / (n * n * n * n * n * n);
  const std::size_t shells = static_cast<std::size_t>(grid_n / 2);
  std::vector<double> sum_k(shells + 1, 0.0), sum_power(shells + 1, 0.0);
  std::vector<double> modes(shells + 1, 0.0);
  const std::size_t un = static_cast<std::size_t>(grid_n);
  for (std::size_t i = 0; i < un; ++i) {
    for (std::size_t j = 0; j < un; ++j) {
      for (std::size_t k = 0; k < grid.complex_nz(); ++k) {
        const double fi = grid.Frequency(i), fj = grid.Frequency(j), fk = grid.Frequency(k);
        const double radius = std::sqrt(fi * fi + fj * fj + fk * fk);
        const auto shell = static_cast<std::size_t>(std::lround(radius));
        if (shell == 0 || shell > shells) continue;
        // Modes with 0 < k_z < n/2 stand for their conjugate too.
        const double multiplicity = (k == 0 || grid.IsNyquist(k)) ? 1.0 : 2.0;
        const double window = CicWindow(grid, i, j, k);
        const double power = std::norm(grid.Mode(i, j, k)) * to_power / (window * window);
        sum_k[shell] += multiplicity * radius;
        sum_power[shell] += multiplicity * power;
        modes[shell] += multiplicity;
      }
    }
  }
  const double fundamental = 2.0 * std::numbers::pi / box;
  std::vector<PowerSpectrumBin> bins;
  for (std::size_t shell = 1; shell <= shells; ++shell) {
    if (modes[shell] == 0.0) continue;
    bins.push_back({fundamental * sum_k[shell] / modes[shell], sum_power[shell] / modes[shell],
                    static_cast<std::size_t>(modes[shell])});
  }
  return bins;
}

}  // namespace octocosm::synth
