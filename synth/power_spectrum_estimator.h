// Measures the power spectrum of a set of particles in a periodic box: CIC
// assignment to a grid, FFT, |delta_k|^2 divided by the CIC window squared,
// averaged in spherical shells of width one fundamental mode k_f = 2 pi / L.
// Shell b (b >= 1) holds the modes with round(|k| / k_f) = b, up to the
// Nyquist frequency of the grid. No shot-noise subtraction: particles that
// start on a lattice have far less than Poisson noise.
//
// Units follow the box: k in 1/length, P in length^3, with the convention of
// linear_power.h, so a measurement in Mpc/h compares directly with
// LinearPowerSpectrum times D(a)^2.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

namespace octocosm::synth {

struct PowerSpectrumBin {
  double k = 0.0;           // mean |k| of the modes in the shell
  double power = 0.0;       // mean P over those modes
  std::size_t modes = 0;    // number of modes, counting k and -k separately
};

// positions: x,y,z interleaved. Returns one entry per shell 1..grid_n/2
// (empty shells are left out).
std::vector<PowerSpectrumBin> MeasurePowerSpectrum(std::span<const double> positions, double box, int grid_n,
                                                   int threads);

}  // namespace octocosm::synth
