// The linear matter power spectrum at z = 0 used for the initial conditions:
// P(k) = A k^n_s T(k)^2 with the Eisenstein & Hu (1998, ApJ 496, 605,
// eqs. 26-31) "no-wiggle" transfer function, and A fixed so that the rms of
// the linear density in top-hat spheres of radius 8 Mpc/h equals sigma8.
//
// Units: k in h/Mpc, P in (Mpc/h)^3, with the Fourier convention
// <delta(k) delta*(k')> = (2 pi)^3 delta_D(k - k') P(k).
#pragma once

#include "synth/cosmology.h"

namespace octocosm::synth {

class LinearPowerSpectrum {
 public:
  explicit LinearPowerSpectrum(const CosmologyParameters& parameters);

  // Eisenstein-Hu no-wiggle transfer function, T(k -> 0) = 1.
  double Transfer(double k) const;
  // P(k) at z = 0; scale by D(a)^2 for another epoch. P(0) = 0.
  double operator()(double k) const;
  // rms linear density at z = 0 in a top-hat sphere of radius r (Mpc/h).
  double SigmaTopHat(double radius) const;

 private:
  double UnnormalisedSigma2(double radius) const;

  CosmologyParameters parameters_;
  double sound_horizon_mpc_;  // s in Mpc (not Mpc/h), EH eq. 26
  double alpha_gamma_;        // EH eq. 31
  double amplitude_ = 1.0;
};

}  // namespace octocosm::synth
