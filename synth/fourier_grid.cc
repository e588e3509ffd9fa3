#include "synth/fourier_grid.h"

#include <fftw3.h>

#include <cstring>
#include <string>

#include "base/error.h"
#include "base/mutex.h"
#include "base/parallel_for.h"

namespace octocosm::synth {
namespace {

Mutex& PlannerMutex() {
  static Mutex mutex;
  return mutex;
}

void DestroyPlan(void* plan) {
  if (plan != nullptr) fftw_destroy_plan(static_cast<fftw_plan>(plan));
}

}  // namespace

FourierGrid::FourierGrid(int n, int threads)
    : n_(n), threads_(threads), padded_(2 * (static_cast<std::size_t>(n) / 2 + 1)) {
  if (n < 2) throw Error::InvalidArgument("Fourier grid size must be at least 2, got " + std::to_string(n));
  plane_ = (static_cast<std::size_t>(n) * padded_ + 7) / 8 * 8;
  const std::size_t count = static_cast<std::size_t>(n) * plane_;
  data_ = static_cast<double*>(fftw_malloc(count * sizeof(double)));
  if (data_ == nullptr) {
    throw Error::InvalidArgument("cannot allocate a " + std::to_string(n) + "^3 Fourier grid (" +
                                 std::to_string(count * sizeof(double) >> 20) + " MiB)");
  }
  std::memset(data_, 0, count * sizeof(double));
  const int nz = n / 2 + 1;
  auto* column_buffer = fftw_alloc_complex(static_cast<std::size_t>(n) * nz);
  {
    MutexLock lock(PlannerMutex());
    auto* complex_data = reinterpret_cast<fftw_complex*>(data_);
    plane_forward_ = fftw_plan_dft_r2c_2d(n, n, data_, complex_data, FFTW_ESTIMATE);
    plane_inverse_ = fftw_plan_dft_c2r_2d(n, n, complex_data, data_, FFTW_ESTIMATE);
    // Row buffer [i][k]: transform along i (stride nz) for each of nz columns.
    const int length[1] = {n};
    if (column_buffer != nullptr) {
      column_forward_ = fftw_plan_many_dft(1, length, nz, column_buffer, nullptr, nz, 1, column_buffer, nullptr, nz, 1,
                                           FFTW_FORWARD, FFTW_ESTIMATE);
      column_inverse_ = fftw_plan_many_dft(1, length, nz, column_buffer, nullptr, nz, 1, column_buffer, nullptr, nz, 1,
                                           FFTW_BACKWARD, FFTW_ESTIMATE);
    }
  }
  fftw_free(column_buffer);
  if (plane_forward_ == nullptr || plane_inverse_ == nullptr || column_forward_ == nullptr ||
      column_inverse_ == nullptr) {
    Release();
    throw Error::InvalidArgument("FFTW could not plan a " + std::to_string(n) + "^3 transform");
  }
}

FourierGrid::~FourierGrid() { Release(); }

void FourierGrid::Release() {
  MutexLock lock(PlannerMutex());
  DestroyPlan(plane_forward_);
  DestroyPlan(plane_inverse_);
  DestroyPlan(column_forward_);
  DestroyPlan(column_inverse_);
  fftw_free(data_);
}

void FourierGrid::Clear() { std::memset(data_, 0, static_cast<std::size_t>(n_) * plane_ * sizeof(double)); }

void FourierGrid::TransformColumns(void* plan) {
  const std::size_t n = static_cast<std::size_t>(n_);
  const std::size_t nz = complex_nz();
  auto* modes = reinterpret_cast<fftw_complex*>(data_);
  const std::size_t plane_modes = plane_ / 2;
  ParallelFor(
      n,
      threads_,
      [&](std::size_t begin, std::size_t end) {
        fftw_complex* buffer = fftw_alloc_complex(n * nz);
        if (buffer == nullptr) throw Error::InvalidArgument("cannot allocate an FFT row buffer");
        for (std::size_t j = begin; j < end; ++j) {
          for (std::size_t i = 0; i < n; ++i) {
            std::memcpy(buffer + i * nz, modes + i * plane_modes + j * nz, nz * sizeof(fftw_complex));
          }
          fftw_execute_dft(static_cast<fftw_plan>(plan), buffer, buffer);
          for (std::size_t i = 0; i < n; ++i) {
            std::memcpy(modes + i * plane_modes + j * nz, buffer + i * nz, nz * sizeof(fftw_complex));
          }
        }
        fftw_free(buffer);
      },
      1);
}

void FourierGrid::TransformPlanes(bool forward) {
  auto* modes = reinterpret_cast<fftw_complex*>(data_);
  ParallelFor(
      static_cast<std::size_t>(n_),
      threads_,
      [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
          double* values = data_ + i * plane_;
          fftw_complex* plane_modes = modes + i * (plane_ / 2);
          if (forward) {
            fftw_execute_dft_r2c(static_cast<fftw_plan>(plane_forward_), values, plane_modes);
          } else {
            fftw_execute_dft_c2r(static_cast<fftw_plan>(plane_inverse_), plane_modes, values);
          }
        }
      },
      1);
}

void FourierGrid::Forward() {
  TransformPlanes(true);
  TransformColumns(column_forward_);
}

void FourierGrid::Inverse() {
  TransformColumns(column_inverse_);
  TransformPlanes(false);
}

}  // namespace octocosm::synth
