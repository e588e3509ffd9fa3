#include "synth/cosmology.h"

#include <cmath>
#include <string>

#include "base/error.h"

namespace octocosm::synth {
namespace {

// Composite Simpson's rule with an even number of intervals. The integrands
// here are smooth on the ranges they are used on, so a fixed count is enough
// for relative accuracy far below 1e-8.
template <typename Function>
double Simpson(Function&& f, double lo, double hi, int intervals) {
  const double h = (hi - lo) / intervals;
  double sum = f(lo) + f(hi);
  for (int i = 1; i < intervals; ++i) sum += f(lo + i * h) * ((i % 2 == 1) ? 4.0 : 2.0);
  return sum * h / 3.0;
}

void Require(bool condition, const std::string& what) {
  if (!condition) throw Error::InvalidArgument("cosmology: " + what);
}

}  // namespace

Cosmology::Cosmology(const CosmologyParameters& parameters) : parameters_(parameters) {
  const CosmologyParameters& p = parameters_;
  Require(std::isfinite(p.omega_matter) && p.omega_matter > 0.0 && p.omega_matter <= 10.0,
          "Omega_m must be in (0, 10], got " + std::to_string(p.omega_matter));
  Require(std::isfinite(p.omega_lambda) && p.omega_lambda >= 0.0 && p.omega_lambda <= 10.0,
          "Omega_Lambda must be in [0, 10], got " + std::to_string(p.omega_lambda));
  Require(std::isfinite(p.omega_baryon) && p.omega_baryon >= 0.0 && p.omega_baryon < p.omega_matter,
          "Omega_b must be in [0, Omega_m), got " + std::to_string(p.omega_baryon));
  Require(std::isfinite(p.hubble) && p.hubble > 0.0 && p.hubble < 10.0,
          "h must be in (0, 10), got " + std::to_string(p.hubble));
  Require(std::isfinite(p.sigma8) && p.sigma8 > 0.0 && p.sigma8 < 10.0,
          "sigma8 must be in (0, 10), got " + std::to_string(p.sigma8));
  Require(std::isfinite(p.spectral_index) && std::abs(p.spectral_index - 1.0) < 1.0,
          "spectral index must be in (0, 2), got " + std::to_string(p.spectral_index));
  omega_curvature_ = 1.0 - p.omega_matter - p.omega_lambda;
  // A closed universe that recollapses before today (E^2 <= 0 somewhere in
  // (0, 1]) has no run to offer; E^2 is smallest where its derivative vanishes
  // or at an end, so checking a fine grid is enough.
  for (int i = 1; i <= 1000; ++i) {
    const double a = i / 1000.0;
    const double e2 = p.omega_matter / (a * a * a) + omega_curvature_ / (a * a) + p.omega_lambda;
    Require(e2 > 0.0, "H(a)^2 <= 0 at a = " + std::to_string(a) +
                          ": Omega_m and Omega_Lambda describe a universe that never reaches today");
  }
  growth_today_ = UnnormalisedGrowth(1.0);
}

double Cosmology::HubbleRate(double a) const {
  const CosmologyParameters& p = parameters_;
  return std::sqrt(p.omega_matter / (a * a * a) + omega_curvature_ / (a * a) + p.omega_lambda);
}

double Cosmology::GrowthIntegral(double a) const {
  // Substituting a' = s^2 turns the a'^(3/2) behaviour near 0 into a smooth
  // polynomial in s, so Simpson's rule converges fast.
  auto integrand = [this](double s) {
    if (s == 0.0) return 0.0;
    const double ap = s * s;
    const double ae = ap * HubbleRate(ap);
    return 2.0 * s / (ae * ae * ae);
  };
  return Simpson(integrand, 0.0, std::sqrt(a), 2048);
}

double Cosmology::UnnormalisedGrowth(double a) const {
  return 2.5 * parameters_.omega_matter * HubbleRate(a) * GrowthIntegral(a);
}

double Cosmology::GrowthFactor(double a) const { return UnnormalisedGrowth(a) / growth_today_; }

double Cosmology::GrowthRate(double a) const {
  // D = 2.5 Om E I with I' = 1/(aE)^3, so dlnD/dlna = a E'/E + 1/(a^2 E^3 I).
  const CosmologyParameters& p = parameters_;
  const double e = HubbleRate(a);
  const double de_da = (-3.0 * p.omega_matter / (a * a * a * a) - 2.0 * omega_curvature_ / (a * a * a)) / (2.0 * e);
  return a * de_da / e + 1.0 / (a * a * e * e * e * GrowthIntegral(a));
}

double Cosmology::DriftFactor(double a0, double a1) const {
  return Simpson([this](double a) { return 1.0 / (a * a * a * HubbleRate(a)); }, a0, a1, 256);
}

double Cosmology::KickFactor(double a0, double a1) const {
  return Simpson([this](double a) { return 1.0 / (a * a * HubbleRate(a)); }, a0, a1, 256);
}

}  // namespace octocosm::synth
