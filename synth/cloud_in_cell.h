// Cloud-in-cell (CIC) mass assignment of particles onto a periodic grid
// (Hockney & Eastwood 1988, ch. 5): each particle is a uniform cube one cell
// wide, and each of the 8 nearest grid points receives the fraction of the
// cube that overlaps its cell. Interpolation back to particles (in
// pm_gravity.cc) uses the same weights, which is what makes the total PM
// force on all particles vanish, so momentum is conserved.
#pragma once

#include <cmath>
#include <cstddef>
#include <span>

#include "synth/fourier_grid.h"

namespace octocosm::synth {

// The 2 grid points along one axis that a particle at x (in cells) touches,
// and their weights.
struct CicAxis {
  std::size_t lower;
  std::size_t upper;       // (lower + 1) mod n
  double upper_weight;     // in [0, 1); the lower point gets 1 - upper_weight
};

inline CicAxis CicAlongAxis(double x_in_cells, int n) {
  double cell = std::floor(x_in_cells);
  double fraction = x_in_cells - cell;
  long index = static_cast<long>(cell) % n;
  if (index < 0) index += n;
  // Rounding can put x_in_cells a hair below n, giving fraction == 1.
  if (fraction >= 1.0) fraction = 0.0, index = (index + 1) % n;
  const auto lower = static_cast<std::size_t>(index);
  return {lower, (lower + 1) % static_cast<std::size_t>(n), fraction};
}

// Adds weight * (CIC share) of every particle to grid.Real(). positions holds
// x,y,z interleaved in the same length unit as box; positions outside
// [0, box) are wrapped periodically. Runs on the calling thread only: the
// summation order, and so every bit of the result, is fixed.
void DepositCic(std::span<const double> positions, double box, double weight, FourierGrid& grid);

// The CIC window W(k) = prod_d sinc^2(k_d dx / 2) of mode (i, j, k) of grid:
// the factor by which assignment smooths that mode. Dividing a deposited
// density by W undoes the assignment; by W^2, assignment and interpolation.
double CicWindow(const FourierGrid& grid, std::size_t i, std::size_t j, std::size_t k);

}  // namespace octocosm::synth
