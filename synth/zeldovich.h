// Zel'dovich (1970) initial conditions: the linear displacement field of a
// Gaussian random density field with a given power spectrum.
//
// Method: n^3 independent unit Gaussians on the particle lattice (a seeded,
// portable generator, random.h) are Fourier transformed, so the modes are
// Hermitian by construction (a real field has a Hermitian transform; FFTW's
// half-complex layout stores each conjugate pair once). Each mode is scaled
// to the amplitude sqrt(P(k) V) and turned into the displacement
// psi(k) = i k / k^2 delta(k), which gives delta = -div psi. The k = 0 mode
// and every mode on a Nyquist plane are set to zero: the Nyquist modes are
// their own conjugates, so multiplying them by i k would make the field
// complex. Three inverse transforms give psi_x, psi_y, psi_z on the lattice.
//
// The field is the linear one at z = 0 (D = 1); a particle at lattice point q
// sits at x = q + D(a) psi(q) at epoch a.
#pragma once

#include <cstdint>
#include <span>

#include "synth/linear_power.h"

namespace octocosm::synth {

// Fills displacement (3 n^3 values, x,y,z interleaved, in the unit of box)
// for the lattice point (i, j, k) at index (i*n + j)*n + k.
void ZeldovichDisplacement(int n, double box, const LinearPowerSpectrum& power, std::uint64_t seed, int threads,
                           std::span<double> displacement);

}  // namespace octocosm::synth
