// Background cosmology of a flat or curved Lambda-CDM universe, in the units
// the particle-mesh integrator uses: time in 1/H0, length in Mpc/h, so that
// H0 = 1 and a velocity of 1 is 100 km/s.
//
// Provides the expansion rate E(a) = H(a)/H0, the linear growth factor D(a)
// (normalised to D(1) = 1) and its logarithmic rate f = dlnD/dlna, and the
// exact drift and kick factors of the leapfrog integrator (docs/SYNTH.md
// derives them). All functions are pure and thread-safe.
#pragma once

namespace octocosm::synth {

struct CosmologyParameters {
  double omega_matter = 0.3;
  double omega_lambda = 0.7;
  double omega_baryon = 0.049;   // only shapes the transfer function; the run is dark matter only
  double hubble = 0.7;           // h, H0 = 100 h km/s/Mpc
  double sigma8 = 0.8;           // rms linear density in 8 Mpc/h top-hat spheres at z = 0
  double spectral_index = 0.965;
};

class Cosmology {
 public:
  // Throws Error::InvalidArgument when a parameter is outside its physical
  // range (Omega_m <= 0, h <= 0, sigma8 <= 0, baryons > matter, ...).
  explicit Cosmology(const CosmologyParameters& parameters);

  const CosmologyParameters& parameters() const { return parameters_; }

  // H(a)/H0 = sqrt(Om a^-3 + Ok a^-2 + OL), Ok = 1 - Om - OL.
  double HubbleRate(double a) const;

  // Linear growing mode of the density contrast, D(1) = 1.
  double GrowthFactor(double a) const;
  // f(a) = dlnD/dlna.
  double GrowthRate(double a) const;

  // Integral from a0 to a1 of da / (a^3 E(a)): the drift factor, so that
  // x(a1) = x(a0) + p * DriftFactor with p = a^2 dx/dt the canonical momentum.
  double DriftFactor(double a0, double a1) const;
  // Integral from a0 to a1 of da / (a^2 E(a)): the kick factor, so that
  // p(a1) = p(a0) - 1.5 Om * grad(phi) * KickFactor with laplacian(phi) = delta.
  double KickFactor(double a0, double a1) const;

 private:
  // Integral from 0 to a of da' / (a' E(a'))^3, the growth integral.
  double GrowthIntegral(double a) const;
  double UnnormalisedGrowth(double a) const;

  CosmologyParameters parameters_;
  double omega_curvature_;
  double growth_today_;
};

}  // namespace octocosm::synth
