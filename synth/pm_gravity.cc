#include "synth/pm_gravity.h"

#include <numbers>

#include "base/error.h"
#include "synth/cloud_in_cell.h"
#include "base/parallel_for.h"

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
  }, 1);
  grid_.Inverse();
}

void PmGravity::InterpolateGradient(std::span<const double> positions, double scale, std::span<double> out) const {
  const int n = grid_.n();
  const std::size_t un = static_cast<std::size_t>(n);
  const double cells_per_length = n / box_;
  // -grad over 12 dx, dx = box / n.
  const double difference_scale = -scale * cells_per_length / 12.0;
  const std::size_t count = positions.size() / 3;
  // Offsets are within -2..+3 of an index in [0, n): one add or subtract
  // wraps them, much cheaper than a division. Grids of 2 or 3 cells need a
  // second pass.
  const long ln = static_cast<long>(un);
  auto wrap = [ln](std::size_t i, long offset) {
    long index = static_cast<long>(i) + offset;
    while (index < 0) index += ln;
    while (index >= ln) index -= ln;
    return static_cast<std::size_t>(index);
  };
  ParallelFor(count, threads_, [&](std::size_t begin, std::size_t end) {
    for (std::size_t p = begin; p < end; ++p) {
      const CicAxis axes[3] = {CicAlongAxis(positions[3 * p] * cells_per_length, n),
                               CicAlongAxis(positions[3 * p + 1] * cells_per_length, n),
                               CicAlongAxis(positions[3 * p + 2] * cells_per_length, n)};
      // Grid indices at offsets -2..+3 from the lower CIC point along each
      // axis: the 4-point stencils of both CIC points need all six.
      std::size_t ix[6], iy[6], iz[6];
      for (int o = 0; o < 6; ++o) {
        ix[o] = wrap(axes[0].lower, o - 2);
        iy[o] = wrap(axes[1].lower, o - 2);
        iz[o] = wrap(axes[2].lower, o - 2);
      }
      // Rows (x, y) the stencils touch: the cross of x offsets 0..5 with y
      // offsets 2..3 and of x offsets 2..3 with y offsets 0..5.
      const double* row[6][6] = {};
      for (int a = 0; a < 6; ++a) {
        for (int b = 0; b < 6; ++b) {
          if ((a == 2 || a == 3) || (b == 2 || b == 3)) row[a][b] = grid_.RealRow(ix[a], iy[b]);
        }
      }
      const double wx[2] = {1.0 - axes[0].upper_weight, axes[0].upper_weight};
      const double wy[2] = {1.0 - axes[1].upper_weight, axes[1].upper_weight};
      const double wz[2] = {1.0 - axes[2].upper_weight, axes[2].upper_weight};
      double force[3] = {0.0, 0.0, 0.0};
      for (int a = 0; a < 2; ++a) {
        for (int b = 0; b < 2; ++b) {
          const int x0 = a + 2, y0 = b + 2;  // this node's offsets in ix, iy
          for (int c = 0; c < 2; ++c) {
            const int z0 = c + 2;
            const std::size_t k = iz[z0];
            const double w = wx[a] * wy[b] * wz[c];
            const double gx = 8.0 * (row[x0 + 1][y0][k] - row[x0 - 1][y0][k]) - (row[x0 + 2][y0][k] - row[x0 - 2][y0][k]);
            const double gy = 8.0 * (row[x0][y0 + 1][k] - row[x0][y0 - 1][k]) - (row[x0][y0 + 2][k] - row[x0][y0 - 2][k]);
            const double* centre = row[x0][y0];
            const double gz =
                8.0 * (centre[iz[z0 + 1]] - centre[iz[z0 - 1]]) - (centre[iz[z0 + 2]] - centre[iz[z0 - 2]]);
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
