#include "synth/linear_power.h"

#include <cmath>
#include <numbers>

namespace octocosm::synth {
namespace {

constexpr double kCmbTemperature = 2.7255;  // K, Fixsen 2009

}  // namespace

LinearPowerSpectrum::LinearPowerSpectrum(const CosmologyParameters& parameters) : parameters_(parameters) {
  // Validates the parameters with the same rules as the background.
  Cosmology validated(parameters);
  (void)validated;
  const double h2 = parameters.hubble * parameters.hubble;
  const double omh2 = parameters.omega_matter * h2;
  const double obh2 = parameters.omega_baryon * h2;
  const double baryon_fraction = parameters.omega_baryon / parameters.omega_matter;
  sound_horizon_mpc_ = 44.5 * std::log(9.83 / omh2) / std::sqrt(1.0 + 10.0 * std::pow(obh2, 0.75));
  alpha_gamma_ = 1.0 - 0.328 * std::log(431.0 * omh2) * baryon_fraction +
                 0.38 * std::log(22.3 * omh2) * baryon_fraction * baryon_fraction;
  amplitude_ = 1.0;
  const double sigma8 = std::sqrt(UnnormalisedSigma2(8.0));
  amplitude_ = (parameters.sigma8 / sigma8) * (parameters.sigma8 / sigma8);
}

double LinearPowerSpectrum::Transfer(double k) const {
  const double h = parameters_.hubble;
  const double theta = kCmbTemperature / 2.7;
  const double ks = 0.43 * k * h * sound_horizon_mpc_;
  const double gamma_eff =
      parameters_.omega_matter * h * (alpha_gamma_ + (1.0 - alpha_gamma_) / (1.0 + ks * ks * ks * ks));
  const double q = k * theta * theta / gamma_eff;
  const double l0 = std::log(2.0 * std::numbers::e + 1.8 * q);
  const double c0 = 14.2 + 731.0 / (1.0 + 62.5 * q);
  return l0 / (l0 + c0 * q * q);
}

double LinearPowerSpectrum::operator()(double k) const {
  if (k <= 0.0) return 0.0;
  const double t = Transfer(k);
  return amplitude_ * std::pow(k, parameters_.spectral_index) * t * t;
}

double LinearPowerSpectrum::UnnormalisedSigma2(double radius) const {
  // sigma^2 = 1/(2 pi^2) int k^3 P(k) W(kR)^2 dlnk, W the top-hat window.
  // Simpson in ln k over 1e-5..1e3 h/Mpc; the window kills the integrand
  // long before the upper end.
  const double lo = std::log(1e-5);
  const double hi = std::log(1e3);
  const int intervals = 4096;
  const double step = (hi - lo) / intervals;
  auto integrand = [&](double lnk) {
    const double k = std::exp(lnk);
    const double x = k * radius;
    const double window = (x < 1e-3) ? 1.0 - x * x / 10.0 : 3.0 * (std::sin(x) - x * std::cos(x)) / (x * x * x);
    return k * k * k * (*this)(k) * window * window;
  };
  double sum = integrand(lo) + integrand(hi);
  for (int i = 1; i < intervals; ++i) sum += integrand(lo + i * step) * ((i % 2 == 1) ? 4.0 : 2.0);
  return sum * step / 3.0 / (2.0 * std::numbers::pi * std::numbers::pi);
}

double LinearPowerSpectrum::SigmaTopHat(double radius) const { return std::sqrt(UnnormalisedSigma2(radius)); }

}  // namespace octocosm::synth
