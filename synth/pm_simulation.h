// The state of a particle-mesh N-body run and its time integrator.
//
// n^3 dark-matter particles in a periodic comoving box of side L (Mpc/h).
// Each particle carries its comoving position x (in [0, L)) and canonical
// momentum p = a^2 dx/dt, with t in units of 1/H0, so p is in Mpc/h * H0
// (100 km/s). Particle index (i*n + j)*n + k started at lattice point
// (i, j, k) L/n and has GADGET ID index + 1.
//
// Equations of motion (docs/SYNTH.md):
//   dx/da = p / (a^3 E(a)),
//   dp/da = -(3/2) Omega_m grad(phi) / (a^2 E(a)),  laplacian(phi) = delta,
// integrated by kick-drift-kick leapfrog whose kick and drift factors are the
// exact integrals of the a-dependent coefficients over each (half) step.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "synth/cosmology.h"
#include "synth/linear_power.h"
#include "synth/pm_gravity.h"

namespace octocosm::synth {

struct PmSimulationOptions {
  int particles_per_side = 64;     // n: n^3 particles
  int grid_factor = 2;             // PM grid of grid_factor * n cells per side (1 or 2)
  double box_size = 100.0;         // L in Mpc/h
  CosmologyParameters cosmology;
  std::uint64_t seed = 1;
  double a_start = 0.02;
  bool deconvolve_cic = false;     // divide the Green's function by W_CIC(k)^2 (see docs/SYNTH.md)
  int threads = 0;                 // 0: all hardware threads
};

class PmSimulation {
 public:
  // Builds Zel'dovich initial conditions at options.a_start. Throws
  // Error::InvalidArgument for out-of-range options.
  explicit PmSimulation(const PmSimulationOptions& options);

  // Advances from a() through each boundary in turn (increasing, all above
  // a()), one leapfrog step per interval, and leaves positions and momenta
  // synchronised at the last boundary. Costs one force evaluation per
  // boundary plus one. after_step(step_index, a) runs after each step; in
  // it, positions are at a but momenta are half a step ahead, except after
  // the last step.
  void Evolve(std::span<const double> boundaries,
              const std::function<void(std::size_t, double)>& after_step = nullptr);

  double a() const { return a_; }
  std::size_t particle_count() const { return momenta_.size() / 3; }
  const PmSimulationOptions& options() const { return options_; }
  const Cosmology& cosmology() const { return cosmology_; }
  const LinearPowerSpectrum& linear_power() const { return power_; }

  std::span<const double> positions() const { return positions_; }  // Mpc/h, x,y,z interleaved
  std::span<const double> momenta() const { return momenta_; }      // p = a^2 dx/dt, x,y,z interleaved

  // Factor turning a momentum into GADGET's velocity (peculiar velocity /
  // sqrt(a), km/s) at the current epoch: 100 km/s / a^(3/2).
  double GadgetVelocityFactor() const;
  // Mass of one particle in 1e10 Msun/h: Omega_m rho_crit L^3 / n^3.
  double ParticleMass() const;

 private:
  void Kick(double factor);
  void Drift(double factor);

  PmSimulationOptions options_;
  Cosmology cosmology_;
  LinearPowerSpectrum power_;
  std::vector<double> positions_;
  std::vector<double> momenta_;
  PmGravity gravity_;
  double a_;
};

}  // namespace octocosm::synth
