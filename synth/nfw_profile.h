// The Navarro-Frenk-White halo profile (Navarro, Frenk & White 1997) as the
// scale mode samples it: enclosed mass, a concentration-mass relation, and a
// table that turns a uniform deviate into a radius in O(1).
//
// With x = r / r_s and concentration c = r_200 / r_s, the mass inside r is
//   M(<r) = M_200 * m(x) / m(c),   m(x) = ln(1 + x) - x / (1 + x),
// for a profile truncated at r_200 (no mass beyond it). The radius of a
// particle is drawn by inverse transform: solve m(c q) / m(c) = u for
// q = r / r_200 with u uniform on [0, 1).
#pragma once

#include <cstddef>
#include <vector>

namespace octocosm::synth {

// m(x) = ln(1 + x) - x / (1 + x), accurate also for small x (where the two
// terms nearly cancel).
double NfwMassShape(double x);

// Fraction of a truncated NFW halo's mass inside q = r / r_200 (0 <= q <= 1;
// clamped outside).
double NfwEnclosedFraction(double concentration, double q);

// Concentration of a halo of M_200 (200 times the mean matter density) at
// z = 0 from the power law fitted by Duffy et al. 2008 (MNRAS 390, L64,
// Table 1, full sample, Delta = 200 mean): c = 10.14 (M / 2e12 Msun/h)^-0.081.
double DuffyConcentration(double mass_msun_h);

// Inverse-CDF tables for a fixed grid of concentrations. Halos use the grid
// concentration nearest (in log c) to their own, so every sampled halo is an
// exact NFW profile of the concentration it reports.
//
// Each table holds q at evenly spaced s = sqrt(u): near the centre m(x) ~ x^2
// / 2, so q grows like sqrt(u) and would be badly served by linear
// interpolation in u, while q(s) is smooth on the whole of [0, 1].
class NfwRadiusTable {
 public:
  static constexpr double kMinConcentration = 2.0;
  static constexpr double kMaxConcentration = 25.0;
  static constexpr int kConcentrations = 48;  // adjacent grid values differ by 5.5%
  static constexpr int kIntervals = 512;      // linear interpolation error in q below 1e-5

  NfwRadiusTable();

  // Index of the grid concentration nearest to `concentration` (clamped to
  // the grid's range).
  int NearestIndex(double concentration) const;
  double Concentration(int index) const { return concentrations_[index]; }

  // q = r / r_200 in [0, 1] with enclosed fraction u (0 <= u < 1) for the
  // grid concentration `index`.
  double Radius(int index, double u) const;

 private:
  std::vector<double> concentrations_;
  std::vector<double> radii_;  // kConcentrations rows of kIntervals + 1 values
};

}  // namespace octocosm::synth
