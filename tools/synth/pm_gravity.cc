#include "tools/synth/pm_gravity.h"

#include <numbers>

#include "storage/error.h"
#include "tools/synth/cloud_in_cell.h"
#include "tools/synth/parallel_for.h"

namespace octocosm::synth {

PmGravity::PmGravity(int grid_n, double box, bool deconvolve_cic, int threads)
    : box_(box), deconvolve_cic_(deconvolve_cic), threads_(threads), grid_(grid_n, threads) {}

void PmGravity::AddScaledForces(std::span<const double> positions, double scale, std::span<double> out) {
  if (positions.size() != out.size() || positions.size() % 3 != 0) {
    throw Error::InvalidArgument("PmGravity: positions and forces must both hold 3 values per particle");
  }
  const std::size_t count = positions.size() / 3;
  if (count == 0) return;
  grid_.Clear();
  // Weight n^3/N_p makes the grid hold 1 + delta; the constant only feeds the
  // k = 0 mode, which the solve discards.
  const double n = grid_.n();
  DepositCic(positions, box_, n * n * n / static_cast<double>(count), grid_);
  SolvePoisson();
  InterpolateGradient(positions, scale, out);
}

void PmGravity::SolvePoisson() {
  grid_.Forward();
  const std::size_t n = static_cast<std::size_t>(grid_.n());
  const double fundamental = 2.0 * std::numbers::pi / box_;
  const double cells = static_cast<double>(grid_.n());
  const double normalisation = 1.0 / (cells * cells * cells);  // undoes the unnormalised round trip
  ParallelFor(n, threads_, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const double kx = fundamental * grid_.Frequency(i);
      for (std::size_t j = 0; j < n; ++j) {
        const double ky = fundamental * grid_.Frequency(j);
        for (std::size_t k = 0; k < grid_.complex_nz(); ++k) {
          const double kz = fundamental * grid_.Frequency(k);
          const double k2 = kx * kx + ky * ky + kz * kz;
          std::complex<double>& mode = grid_.Mode(i, j, k);
          if (k2 == 0.0) {
            mode = 0.0;
            continue;
          }
          double green = -normalisation / k2;
          if (deconvolve_cic_) {
            const double window = CicWindow(grid_, i, j, k);
            green /= window * window;
          }
          mode *= green;
        }
      }
    }
  });
  grid_.Inverse();
}

void PmGravity::InterpolateGradient(std::span<const double> positions, double scale, std::span<double> out) const {
  const int n = grid_.n();
  const std::size_t un = static_cast<std::size_t>(n);
  const double cells_per_length = n / box_;
  // -grad over 12 dx, dx = box / n.
  const double difference_scale = -scale * cells_per_length / 12.0;
  const std::size_t count = positions.size() / 3;
  auto wrap = [un](std::size_t i, long offset) {
    return static_cast<std::size_t>((static_cast<long>(i) + offset + 2 * static_cast<long>(un)) % static_cast<long>(un));
  };
  ParallelFor(count, threads_, [&](std::size_t begin, std::size_t end) {
    for (std::size_t p = begin; p < end; ++p) {
      const CicAxis axes[3] = {CicAlongAxis(positions[3 * p] * cells_per_length, n),
                               CicAlongAxis(positions[3 * p + 1] * cells_per_length, n),
                               CicAlongAxis(positions[3 * p + 2] * cells_per_length, n)};
      // Neighbour indices -2..+3 around the lower point along each axis.
      std::size_t around[3][6];
      double weight[3][2];
      for (int d = 0; d < 3; ++d) {
        for (int o = 0; o < 6; ++o) around[d][o] = wrap(axes[d].lower, o - 2);
        weight[d][0] = 1.0 - axes[d].upper_weight;
        weight[d][1] = axes[d].upper_weight;
      }
      auto phi = [&](std::size_t i, std::size_t j, std::size_t k) { return grid_.Real(i, j, k); };
      double force[3] = {0.0, 0.0, 0.0};
      for (int a = 0; a < 2; ++a) {
        for (int b = 0; b < 2; ++b) {
          for (int c = 0; c < 2; ++c) {
            const double w = weight[0][a] * weight[1][b] * weight[2][c];
            // Centre index of this node in `around` is 2 + offset.
            const std::size_t* ax = around[0] + a;
            const std::size_t* ay = around[1] + b;
            const std::size_t* az = around[2] + c;
            const std::size_t i = ax[2], j = ay[2], k = az[2];
            const double gx = 8.0 * (phi(ax[3], j, k) - phi(ax[1], j, k)) - (phi(ax[4], j, k) - phi(ax[0], j, k));
            const double gy = 8.0 * (phi(i, ay[3], k) - phi(i, ay[1], k)) - (phi(i, ay[4], k) - phi(i, ay[0], k));
            const double gz = 8.0 * (phi(i, j, az[3]) - phi(i, j, az[1])) - (phi(i, j, az[4]) - phi(i, j, az[0]));
            force[0] += w * gx;
            force[1] += w * gy;
            force[2] += w * gz;
          }
        }
      }
      for (int d = 0; d < 3; ++d) out[3 * p + d] += difference_scale * force[d];
    }
  });
}

}  // namespace octocosm::synth
