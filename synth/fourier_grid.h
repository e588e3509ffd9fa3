// A periodic cubic grid of n^3 real values that can be transformed in place
// to and from its n*n*(n/2+1) complex Fourier coefficients with FFTW.
//
// Layout (FFTW's in-place real-to-complex convention, plane by plane): real
// cell (i, j, k) lives at index i*plane + j*padded + k with
// padded = 2*(n/2+1); complex mode (i, j, k), k in [0, n/2], is the pair at
// 2*(i*plane/2 + j*(n/2+1) + k). The plane stride `plane` is n*padded rounded
// up to a multiple of 8 doubles, so that every plane is aligned like the
// first. Modes with k > n/2 are implied by Hermitian symmetry. The transforms
// are unnormalised: Inverse(Forward(x)) = n^3 x.
//
// A 3-D transform is done as n 2-D real transforms of the x-planes followed
// by 1-D complex transforms along x, gathered for each y-row into a small
// contiguous buffer. The gather matters: the columns along x are a plane
// apart, a power-of-two-like stride that made FFTW_ESTIMATE's 3-D plan six
// times slower at 256^3 than this split (measured, 0.18 s vs 1.0 s of CPU per
// forward+inverse pair), as fast as an FFTW_MEASURE 3-D plan. Plans are made
// with FFTW_ESTIMATE, which is deterministic (FFTW_MEASURE may pick another
// algorithm, and so other rounding, in another run), and each plane and row
// is transformed by the same plan on whichever thread, so the result is
// bit-identical for any thread count.
//
// Creating and destroying grids is serialised internally because FFTW's
// planner is not thread-safe; Forward/Inverse on distinct grids may run
// concurrently.
#pragma once

#include <complex>
#include <cstddef>

namespace octocosm::synth {

class FourierGrid {
 public:
  // n >= 2; threads is the number of threads per transform.
  FourierGrid(int n, int threads);
  ~FourierGrid();
  FourierGrid(const FourierGrid&) = delete;
  FourierGrid& operator=(const FourierGrid&) = delete;

  int n() const { return n_; }
  std::size_t padded() const { return padded_; }
  std::size_t complex_nz() const { return static_cast<std::size_t>(n_ / 2 + 1); }

  // Pointer to real cell (i, j, 0); the row holds n values (then padding).
  double* RealRow(std::size_t i, std::size_t j) { return data_ + i * plane_ + j * padded_; }
  const double* RealRow(std::size_t i, std::size_t j) const { return data_ + i * plane_ + j * padded_; }
  double& Real(std::size_t i, std::size_t j, std::size_t k) { return RealRow(i, j)[k]; }
  double Real(std::size_t i, std::size_t j, std::size_t k) const { return RealRow(i, j)[k]; }
  std::complex<double>& Mode(std::size_t i, std::size_t j, std::size_t k) {
    return reinterpret_cast<std::complex<double>*>(data_)[i * (plane_ / 2) + j * complex_nz() + k];
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
  // 1-D transforms along x of every (j, k) column, in the given direction.
  void TransformColumns(void* plan);
  // The 2-D transform of every x-plane, in place: real to modes (forward)
  // or back.
  void TransformPlanes(bool forward);
  // Frees the plans made so far and the data.
  void Release();

  int n_;
  int threads_;
  std::size_t padded_;
  std::size_t plane_;  // doubles from one x-plane to the next
  double* data_ = nullptr;
  void* plane_forward_ = nullptr;   // 2-D r2c of one plane, in place
  void* plane_inverse_ = nullptr;   // 2-D c2r of one plane, in place
  void* column_forward_ = nullptr;  // n_z 1-D transforms of length n on a gathered row
  void* column_inverse_ = nullptr;
};

}  // namespace octocosm::synth
