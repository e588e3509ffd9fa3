#include "synth/nfw_profile.h"

#include <algorithm>
#include <cmath>

namespace octocosm::synth {

double NfwMassShape(double x) {
  // Below x ~ 1e-3 the difference loses digits; the series
  // x^2/2 - 2x^3/3 + 3x^4/4 is exact there to double precision's needs.
  if (x < 1e-3) return x * x * (0.5 - x * (2.0 / 3.0 - 0.75 * x));
  return std::log1p(x) - x / (1.0 + x);
}

double NfwEnclosedFraction(double concentration, double q) {
  q = std::clamp(q, 0.0, 1.0);
  return NfwMassShape(concentration * q) / NfwMassShape(concentration);
}

double DuffyConcentration(double mass_msun_h) {
  return 10.14 * std::pow(mass_msun_h / 2e12, -0.081);
}

NfwRadiusTable::NfwRadiusTable() {
  concentrations_.resize(kConcentrations);
  const double log_step = std::log(kMaxConcentration / kMinConcentration) / (kConcentrations - 1);
  for (int k = 0; k < kConcentrations; ++k) concentrations_[k] = kMinConcentration * std::exp(log_step * k);

  radii_.resize(static_cast<std::size_t>(kConcentrations) * (kIntervals + 1));
  for (int k = 0; k < kConcentrations; ++k) {
    double* row = &radii_[static_cast<std::size_t>(k) * (kIntervals + 1)];
    row[0] = 0.0;
    row[kIntervals] = 1.0;
    for (int i = 1; i < kIntervals; ++i) {
      const double s = static_cast<double>(i) / kIntervals;
      const double target = s * s;
      // Bisection: the enclosed fraction is monotonic in q, and 60 halvings
      // reach double precision from the bracket [0, 1].
      double low = 0.0, high = 1.0;
      for (int iteration = 0; iteration < 60; ++iteration) {
        const double mid = 0.5 * (low + high);
        (NfwEnclosedFraction(concentrations_[k], mid) < target ? low : high) = mid;
      }
      row[i] = 0.5 * (low + high);
    }
  }
}

int NfwRadiusTable::NearestIndex(double concentration) const {
  const double log_step = std::log(kMaxConcentration / kMinConcentration) / (kConcentrations - 1);
  const double position = std::log(concentration / kMinConcentration) / log_step;
  if (!(position > 0.0)) return 0;  // also catches NaN
  return std::min(kConcentrations - 1, static_cast<int>(std::lround(position)));
}

double NfwRadiusTable::Radius(int index, double u) const {
  const double position = std::sqrt(std::clamp(u, 0.0, 1.0)) * kIntervals;
  const int i = std::min(kIntervals - 1, static_cast<int>(position));
  const double fraction = position - i;
  const double* row = &radii_[static_cast<std::size_t>(index) * (kIntervals + 1)];
  return row[i] + fraction * (row[i + 1] - row[i]);
}

}  // namespace octocosm::synth
