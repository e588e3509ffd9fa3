#include "tools/synth/fourier_grid.h"

#include <fftw3.h>

#include <cstring>
#include <mutex>
#include <new>
#include <string>

#include "storage/error.h"

namespace octocosm::synth {
namespace {

std::mutex& PlannerMutex() {
  static std::mutex mutex;
  return mutex;
}

}  // namespace

FourierGrid::FourierGrid(int n, int threads) : n_(n), padded_(2 * (static_cast<std::size_t>(n) / 2 + 1)) {
  if (n < 2) throw Error::InvalidArgument("Fourier grid size must be at least 2, got " + std::to_string(n));
  const std::size_t count = static_cast<std::size_t>(n) * n * padded_;
  data_ = static_cast<double*>(fftw_malloc(count * sizeof(double)));
  if (data_ == nullptr) {
    throw Error::InvalidArgument("cannot allocate a " + std::to_string(n) + "^3 Fourier grid (" +
                                 std::to_string(count * sizeof(double) >> 20) + " MiB)");
  }
  std::memset(data_, 0, count * sizeof(double));
  std::lock_guard<std::mutex> lock(PlannerMutex());
  static const bool threads_ready = fftw_init_threads() != 0;
  fftw_plan_with_nthreads(threads_ready && threads > 1 ? threads : 1);
  auto* complex_data = reinterpret_cast<fftw_complex*>(data_);
  forward_plan_ = fftw_plan_dft_r2c_3d(n, n, n, data_, complex_data, FFTW_ESTIMATE);
  inverse_plan_ = fftw_plan_dft_c2r_3d(n, n, n, complex_data, data_, FFTW_ESTIMATE);
  if (forward_plan_ == nullptr || inverse_plan_ == nullptr) {
    if (forward_plan_ != nullptr) fftw_destroy_plan(static_cast<fftw_plan>(forward_plan_));
    if (inverse_plan_ != nullptr) fftw_destroy_plan(static_cast<fftw_plan>(inverse_plan_));
    fftw_free(data_);
    throw Error::InvalidArgument("FFTW could not plan a " + std::to_string(n) + "^3 transform");
  }
}

FourierGrid::~FourierGrid() {
  std::lock_guard<std::mutex> lock(PlannerMutex());
  fftw_destroy_plan(static_cast<fftw_plan>(forward_plan_));
  fftw_destroy_plan(static_cast<fftw_plan>(inverse_plan_));
  fftw_free(data_);
}

void FourierGrid::Clear() { std::memset(data_, 0, static_cast<std::size_t>(n_) * n_ * padded_ * sizeof(double)); }

void FourierGrid::Forward() { fftw_execute(static_cast<fftw_plan>(forward_plan_)); }

void FourierGrid::Inverse() { fftw_execute(static_cast<fftw_plan>(inverse_plan_)); }

}  // namespace octocosm::synth
