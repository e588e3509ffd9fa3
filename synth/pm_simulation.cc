#include "synth/pm_simulation.h"

#include <cmath>
#include <string>

#include "base/error.h"
#include "base/parallel_for.h"
#include "synth/zeldovich.h"

namespace octocosm::synth {
namespace {

// Critical density today, 3 H0^2 / (8 pi G), in (1e10 Msun/h) / (Mpc/h)^3.
constexpr double kCriticalDensity = 27.7536627;

// The largest n accepted: n^3 positions, momenta and a (2n)^3 grid in
// doubles already take 14 GiB at n = 512.
constexpr int kMaxParticlesPerSide = 512;

const PmSimulationOptions& Validated(const PmSimulationOptions& o) {
  if (o.particles_per_side < 2 || o.particles_per_side > kMaxParticlesPerSide) {
    throw Error::InvalidArgument("particles per side must be in [2, " + std::to_string(kMaxParticlesPerSide) +
                                 "], got " + std::to_string(o.particles_per_side));
  }
  if (o.grid_factor != 1 && o.grid_factor != 2) {
    throw Error::InvalidArgument("PM grid factor must be 1 or 2, got " + std::to_string(o.grid_factor));
  }
  if (!(std::isfinite(o.box_size) && o.box_size > 0.0)) {
    throw Error::InvalidArgument("box size must be positive, got " + std::to_string(o.box_size));
  }
  if (!(std::isfinite(o.a_start) && o.a_start > 0.0 && o.a_start <= 1.0)) {
    throw Error::InvalidArgument("starting expansion factor must be in (0, 1], got " + std::to_string(o.a_start));
  }
  if (o.threads < 0) throw Error::InvalidArgument("thread count must be >= 0");
  return o;
}

double WrapPeriodic(double x, double box) {
  x -= box * std::floor(x / box);
  // A tiny negative x lands exactly on box after the subtraction.
  return x >= box ? 0.0 : x;
}

}  // namespace

PmSimulation::PmSimulation(const PmSimulationOptions& options)
    : options_(Validated(options)),
      cosmology_(options.cosmology),
      power_(options.cosmology),
      gravity_(options.grid_factor * options.particles_per_side, options.box_size, options.deconvolve_cic,
               ResolveThreadCount(options.threads)),
      a_(options.a_start) {
  options_.threads = ResolveThreadCount(options.threads);
  const std::size_t n = static_cast<std::size_t>(options_.particles_per_side);
  const std::size_t count = n * n * n;
  positions_.resize(3 * count);
  momenta_.resize(3 * count);
  // The displacement psi is built in the momentum array, then turned into
  // both x = q + D psi and p = a^2 E f D psi (H0 = 1), the Zel'dovich growing
  // mode: dx/dt = dD/dt psi = H f D psi.
  ZeldovichDisplacement(options_.particles_per_side, options_.box_size, power_, options_.seed, options_.threads,
                        momenta_);
  const double growth = cosmology_.GrowthFactor(a_);
  const double momentum_factor = a_ * a_ * cosmology_.HubbleRate(a_) * cosmology_.GrowthRate(a_) * growth;
  const double spacing = options_.box_size / static_cast<double>(n);
  ParallelFor(n, options_.threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      for (std::size_t j = 0; j < n; ++j) {
        for (std::size_t k = 0; k < n; ++k) {
          const std::size_t p = (i * n + j) * n + k;
          const double lattice[3] = {static_cast<double>(i) * spacing, static_cast<double>(j) * spacing,
                                     static_cast<double>(k) * spacing};
          for (int d = 0; d < 3; ++d) {
            const double psi = momenta_[3 * p + d];
            positions_[3 * p + d] = WrapPeriodic(lattice[d] + growth * psi, options_.box_size);
            momenta_[3 * p + d] = momentum_factor * psi;
          }
        }
      }
    }
  }, 1);
}

double PmSimulation::GadgetVelocityFactor() const { return 100.0 / (a_ * std::sqrt(a_)); }

double PmSimulation::ParticleMass() const {
  const double n = options_.particles_per_side;
  const double l = options_.box_size;
  return kCriticalDensity * cosmology_.parameters().omega_matter * l * l * l / (n * n * n);
}

void PmSimulation::Kick(double factor) {
  // p += factor * (-grad phi), with factor = 1.5 Om * kick integral.
  gravity_.AddScaledForces(positions_, factor, momenta_);
}

void PmSimulation::Drift(double factor) {
  const double box = options_.box_size;
  ParallelFor(positions_.size(), options_.threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) positions_[i] = WrapPeriodic(positions_[i] + factor * momenta_[i], box);
  });
}

void PmSimulation::Evolve(std::span<const double> boundaries,
                          const std::function<void(std::size_t, double)>& after_step) {
  double previous = a_;
  for (double boundary : boundaries) {
    if (!(boundary > previous)) {
      throw Error::InvalidArgument("step boundaries must increase from a = " + std::to_string(a_) + ", got " +
                                   std::to_string(boundary) + " after " + std::to_string(previous));
    }
    previous = boundary;
  }
  if (boundaries.empty()) return;
  const double force_scale = 1.5 * cosmology_.parameters().omega_matter;
  auto midpoint = [](double a0, double a1) { return 0.5 * (a0 + a1); };
  // Opening half kick; each later force evaluation closes one step and
  // opens the next with a single combined kick.
  double a0 = a_;
  Kick(force_scale * cosmology_.KickFactor(a0, midpoint(a0, boundaries[0])));
  for (std::size_t step = 0; step < boundaries.size(); ++step) {
    const double a1 = boundaries[step];
    Drift(cosmology_.DriftFactor(a0, a1));
    a_ = a1;
    const double kick_to = step + 1 < boundaries.size() ? midpoint(a1, boundaries[step + 1]) : a1;
    Kick(force_scale * cosmology_.KickFactor(midpoint(a0, a1), kick_to));
    if (after_step) after_step(step, a1);
    a0 = a1;
  }
}

}  // namespace octocosm::synth
