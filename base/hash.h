// Integer hashing shared by every layer.
#pragma once

#include <cstdint>

namespace octocosm {

// splitmix64's finaliser: a bijection of 64-bit integers in which every
// input bit affects every output bit, enough to turn sequential IDs or dense
// Morton keys into independent-looking values.
inline std::uint64_t MixBits64(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  x ^= x >> 31;
  return x;
}

// splitmix64's increment (2^64 / golden ratio), to offset seeds and keys
// before mixing.
inline constexpr std::uint64_t kGoldenGamma = 0x9e3779b97f4a7c15ull;

// splitmix64: the next value of a stream of uniform 64-bit values whose
// whole state is `state` (seeding generators, reservoir sampling).
inline std::uint64_t SplitMix64(std::uint64_t& state) { return MixBits64(state += kGoldenGamma); }

}  // namespace octocosm
