// XXH3-64 built for AVX2: this file alone is compiled with -mavx2, and
// storage/checksum.cc calls it only on CPUs that have AVX2.
#define XXH_INLINE_ALL
#include <xxhash.h>

#include <cstddef>
#include <cstdint>

namespace octocosm::checksum_internal {

std::uint64_t Xxh3WithAvx2(const void* bytes, std::size_t size) { return XXH3_64bits(bytes, size); }

}  // namespace octocosm::checksum_internal
