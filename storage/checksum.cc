#include "storage/checksum.h"

#include <xxhash.h>

#include <cstdio>
#include <memory>
#include <new>

namespace octocosm {

#if OCTOCOSM_CHECKSUM_AVX2
// Debian builds libxxhash for baseline x86-64, so its XXH3_64bits runs SSE2
// code: about 19 GB/s on a 160 KiB block here, against 60 GB/s built for
// AVX2. The library's own run-time dispatch (XXH3_64bits_dispatch) is faster
// still, but it returns from AVX-512 code without clearing the registers'
// upper halves (no vzeroupper), and every SSE instruction after it then ran
// at half speed: a 10^7-point ingest took 1.24 s instead of 0.96.
namespace checksum_internal {
std::uint64_t Xxh3WithAvx2(const void* bytes, std::size_t size);
}  // namespace checksum_internal

namespace {
// Initialised before main, so the CPU's features are read first explicitly
// (GCC: __builtin_cpu_init before __builtin_cpu_supports in code that may
// run before constructors).
const bool kCpuHasAvx2 = [] {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") != 0;
}();
}  // namespace
#endif

std::uint64_t Checksum64(std::span<const std::uint8_t> bytes) {
#if OCTOCOSM_CHECKSUM_AVX2
  if (kCpuHasAvx2) return checksum_internal::Xxh3WithAvx2(bytes.data(), bytes.size());
#endif
  return XXH3_64bits(bytes.data(), bytes.size());
}

std::uint64_t Checksum64(std::span<const std::uint8_t> first, std::span<const std::uint8_t> second) {
  struct StateDeleter {
    void operator()(XXH3_state_t* state) const { XXH3_freeState(state); }
  };
  std::unique_ptr<XXH3_state_t, StateDeleter> state(XXH3_createState());
  if (!state) throw std::bad_alloc();
  XXH3_64bits_reset(state.get());
  XXH3_64bits_update(state.get(), first.data(), first.size());
  XXH3_64bits_update(state.get(), second.data(), second.size());
  return XXH3_64bits_digest(state.get());
}

std::string Hex64(std::uint64_t value) {
  char text[19];
  std::snprintf(text, sizeof text, "0x%016llx", static_cast<unsigned long long>(value));
  return text;
}

}  // namespace octocosm
