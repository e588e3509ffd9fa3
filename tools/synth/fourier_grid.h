// A periodic cubic grid of n^3 real values that can be transformed in place
// to and from its n*n*(n/2+1) complex Fourier coefficients with FFTW.
//
// Layout (FFTW's in-place real-to-complex convention): real cell (i, j, k)
// lives at index (i*n + j)*padded + k with padded = 2*(n/2+1); complex mode
// (i, j, k), k in [0, n/2], is the pair at 2*((i*n + j)*(n/2+1) + k).
// Modes with k > n/2 are implied by Hermitian symmetry. The transforms are
// unnormalised: Inverse(Forward(x)) = n^3 x.
//
// Plans are made with FFTW_ESTIMATE, which is deterministic: the same input
// always gives the same output bits (FFTW_MEASURE may pick different
// algorithms from run to run). Creating and destroying grids is serialised
// internally because FFTW's planner is not thread-safe; Forward/Inverse on
// distinct grids may run concurrently.
#pragma once

#include <complex>
#include <cstddef>

namespace octocosm::synth {

class FourierGrid {
 public:
  // n >= 2; threads is the number of FFTW threads per transform.
  FourierGrid(int n, int threads);
  ~FourierGrid();
  FourierGrid(const FourierGrid&) = delete;
  FourierGrid& operator=(const FourierGrid&) = delete;

  int n() const { return n_; }
  std::size_t padded() const { return padded_; }
  std::size_t complex_nz() const { return static_cast<std::size_t>(n_ / 2 + 1); }

  double* real() { return data_; }
  const double* real() const { return data_; }
  double& Real(std::size_t i, std::size_t j, std::size_t k) { return data_[(i * n_ + j) * padded_ + k]; }
  double Real(std::size_t i, std::size_t j, std::size_t k) const { return data_[(i * n_ + j) * padded_ + k]; }
  std::complex<double>* modes() { return reinterpret_cast<std::complex<double>*>(data_); }
  std::complex<double>& Mode(std::size_t i, std::size_t j, std::size_t k) {
    return modes()[(i * n_ + j) * complex_nz() + k];
  }

  // Sets every value (including padding) to zero.
  void Clear();
  void Forward();
  void Inverse();

  // Signed frequency index of grid index i: i for i <= n/2, i - n above.
  int Frequency(std::size_t i) const { return static_cast<int>(i) <= n_ / 2 ? static_cast<int>(i) : static_cast<int>(i) - n_; }
  // True when i is the Nyquist index n/2 of an even grid, whose mode has no
  // distinct conjugate partner.
  bool IsNyquist(std::size_t i) const { return n_ % 2 == 0 && static_cast<int>(i) == n_ / 2; }

 private:
  int n_;
  std::size_t padded_;
  double* data_ = nullptr;
  void* forward_plan_ = nullptr;
  void* inverse_plan_ = nullptr;
};

}  // namespace octocosm::synth
