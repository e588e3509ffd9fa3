// Particle-mesh gravity on a periodic comoving grid.
//
// For particle positions x it computes F = -grad(phi) at every particle, where
// laplacian(phi) = delta and delta is the density contrast of the particles
// (mean density subtracted). The integrator scales F by 1.5 Omega_m / a to
// get the physical force (docs/SYNTH.md). Steps:
//   1. CIC assignment of the particles to the grid (cloud_in_cell.h);
//   2. forward FFT, phi_k = -delta_k / k^2 (k = 0 mode set to zero), optionally
//      divided by W_CIC(k)^2 to undo the smoothing of assignment and
//      interpolation;
//   3. inverse FFT to phi on the grid;
//   4. the gradient by the 4-point central difference
//      dphi/dx ~ [8(phi[i+1] - phi[i-1]) - (phi[i+2] - phi[i-2])] / (12 dx),
//      evaluated at the 8 grid points around each particle and CIC-
//      interpolated to it (with the assignment weights, so the total force
//      on all particles is zero to rounding: momentum is conserved).
// Memory: one padded grid of n^3 doubles. Interpolation runs on `threads`
// threads; it writes each particle's force only, so the result does not
// depend on the thread count.
#pragma once

#include <span>

#include "synth/fourier_grid.h"

namespace octocosm::synth {

class PmGravity {
 public:
  // grid_n cells per side over a box of side `box` (any length unit; forces
  // come out in that unit).
  PmGravity(int grid_n, double box, bool deconvolve_cic, int threads);

  // Adds scale * F to out for every particle, where F = -grad(phi) at the
  // particle's position. positions and out are x,y,z interleaved, same size.
  // Accumulating (rather than returning F) lets the integrator kick momenta
  // in place without a third array of n^3 vectors.
  void AddScaledForces(std::span<const double> positions, double scale, std::span<double> out);

 private:
  void SolvePoisson();
  void InterpolateGradient(std::span<const double> positions, double scale, std::span<double> out) const;

  double box_;
  bool deconvolve_cic_;
  int threads_;
  FourierGrid grid_;
};

}  // namespace octocosm::synth
