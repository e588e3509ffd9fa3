// The upload ring (render/upload_ring.h) on OSMesa: whatever the sizes and
// however often it wraps, every byte arrives where it was sent.
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <vector>

#include "render/gl_context.h"
#include "render/gl_objects.h"
#include "render/upload_ring.h"

namespace octocosm {
namespace {

// Pieces of 1 byte to three times the ring, at random offsets of a target,
// wrapping the ring many times (each quarter reused while the GPU may still
// copy from it): the target holds the last bytes sent to each place.
TEST(GlUploadRing, EveryByteArrivesWhereItWasSent) {
  const std::unique_ptr<GlContext> context = CreateHeadlessContext(HeadlessBackend::kOsMesa);
  UploadRing ring(4096);
  const std::size_t target_bytes = 64 * 1024;
  GlBuffer target = MakeGlBuffer(target_bytes, nullptr, GL_DYNAMIC_STORAGE_BIT);
  std::vector<std::uint8_t> expected(target_bytes, 0);
  glClearNamedBufferData(target.get(), GL_R8UI, GL_RED_INTEGER, GL_UNSIGNED_BYTE, expected.data());
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<int> byte(0, 255);
  std::size_t sent = 0;
  for (int round = 0; round < 300; ++round) {
    const std::size_t size = round % 50 == 0 ? 3 * ring.bytes() + 5 : 1 + rng() % 1500;
    const std::size_t offset = rng() % (target_bytes - size);
    std::vector<std::uint8_t> data(size);
    for (std::uint8_t& b : data) b = static_cast<std::uint8_t>(byte(rng));
    ring.Upload(data, target.get(), offset);
    std::copy(data.begin(), data.end(), expected.begin() + static_cast<std::ptrdiff_t>(offset));
    sent += size;
  }
  ASSERT_GT(sent, 20 * ring.bytes()) << "the ring wrapped many times";
  std::vector<std::uint8_t> arrived(target_bytes);
  glGetNamedBufferSubData(target.get(), 0, static_cast<GLsizeiptr>(target_bytes), arrived.data());
  CheckGlError("reading the target back");
  EXPECT_EQ(arrived, expected);
}

}  // namespace
}  // namespace octocosm
