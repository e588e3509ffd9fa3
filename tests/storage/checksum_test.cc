// Checksum64 must be XXH3-64 as docs/FORMAT.md fixes it, whichever code
// computes it: storage/checksum.cc may call xxHash's run-time dispatch (AVX2,
// AVX-512) where the library's plain XXH3_64bits, called here, runs the
// portable code. Lengths cover each of XXH3's paths (0, 1-3, 4-8, 9-16,
// 17-128, 129-240 bytes, then stripes, blocks and a partial last block).
#include "storage/checksum.h"

#include <gtest/gtest.h>
#include <xxhash.h>

#include <cstdint>
#include <vector>

namespace octocosm {
namespace {

std::vector<std::uint8_t> Bytes(std::size_t n) {
  std::vector<std::uint8_t> bytes(n);
  std::uint64_t x = 0x9e3779b97f4a7c15ull;
  for (std::uint8_t& b : bytes) {
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    b = static_cast<std::uint8_t>(x >> 56);
  }
  return bytes;
}

constexpr std::size_t kLengths[] = {0,   1,   3,    4,    8,    9,    16,   17,    128,    129,   240,
                                    241, 255, 1024, 1025, 4096, 8192, 9999, 65536, 160005, 1 << 20};

TEST(Checksum64, IsXxh3OfEveryLength) {
  const std::vector<std::uint8_t> bytes = Bytes(1 << 20);
  for (const std::size_t n : kLengths) {
    const std::span<const std::uint8_t> part(bytes.data(), n);
    EXPECT_EQ(Checksum64(part), XXH3_64bits(part.data(), n)) << n << " bytes";
  }
  EXPECT_EQ(Checksum64(std::span<const std::uint8_t>()), 0x2D06800538D394C2ull);
}

TEST(Checksum64, TwoPartsHashAsTheirConcatenation) {
  const std::vector<std::uint8_t> bytes = Bytes(200000);
  for (const std::size_t n : {std::size_t{0}, std::size_t{24}, std::size_t{300}, std::size_t{200000}}) {
    for (const std::size_t cut : {std::size_t{0}, n / 3, n}) {
      const std::span<const std::uint8_t> whole(bytes.data(), n);
      EXPECT_EQ(Checksum64(whole.first(cut), whole.subspan(cut)), XXH3_64bits(whole.data(), n))
          << n << " bytes cut at " << cut;
    }
  }
}

}  // namespace
}  // namespace octocosm
