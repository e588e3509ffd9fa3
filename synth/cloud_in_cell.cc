#include "synth/cloud_in_cell.h"

#include <numbers>

namespace octocosm::synth {
namespace {

double Sinc(double x) { return x == 0.0 ? 1.0 : std::sin(x) / x; }

}  // namespace

void DepositCic(std::span<const double> positions, double box, double weight, FourierGrid& grid) {
  const int n = grid.n();
  const double cells_per_length = n / box;
  const std::size_t count = positions.size() / 3;
  for (std::size_t p = 0; p < count; ++p) {
    const CicAxis x = CicAlongAxis(positions[3 * p] * cells_per_length, n);
    const CicAxis y = CicAlongAxis(positions[3 * p + 1] * cells_per_length, n);
    const CicAxis z = CicAlongAxis(positions[3 * p + 2] * cells_per_length, n);
    const double wx[2] = {weight * (1.0 - x.upper_weight), weight * x.upper_weight};
    const double wy[2] = {1.0 - y.upper_weight, y.upper_weight};
    const double wz[2] = {1.0 - z.upper_weight, z.upper_weight};
    const std::size_t ix[2] = {x.lower, x.upper};
    const std::size_t iy[2] = {y.lower, y.upper};
    const std::size_t iz[2] = {z.lower, z.upper};
    for (int a = 0; a < 2; ++a) {
      for (int b = 0; b < 2; ++b) {
        double* row = &grid.Real(ix[a], iy[b], 0);
        const double wab = wx[a] * wy[b];
        row[iz[0]] += wab * wz[0];
        row[iz[1]] += wab * wz[1];
      }
    }
  }
}

double CicWindow(const FourierGrid& grid, std::size_t i, std::size_t j, std::size_t k) {
  const double half_step = std::numbers::pi / grid.n();  // k_d dx / 2 per unit frequency
  const double sx = Sinc(half_step * grid.Frequency(i));
  const double sy = Sinc(half_step * grid.Frequency(j));
  const double sz = Sinc(half_step * grid.Frequency(k));
  return sx * sx * sy * sy * sz * sz;
}

}  // namespace octocosm::synth
