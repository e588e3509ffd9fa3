#include "index/particle_chunk.h"

#include <gtest/gtest.h>

namespace octocosm {
namespace {

// A chunk of `n` particles with every column filled, values from `base` up.
ParticleChunk Filled(std::size_t n, int base) {
  ParticleChunk c;
  for (std::size_t i = 0; i < n; ++i) {
    const int v = base + static_cast<int>(i);
    for (int a = 0; a < 3; ++a) c.position.push_back(v + 0.25 * a);
    c.mass.push_back(v);
    c.id.push_back(static_cast<std::uint64_t>(v));
    c.type.push_back(static_cast<std::uint8_t>(v % 6));
    c.smoothing.push_back(static_cast<float>(v) / 2);
    for (std::vector<float>* column : VectorColumns(c)) {
      for (int a = 0; a < 3; ++a) column->push_back(static_cast<float>(v) + static_cast<float>(a) / 4);
    }
  }
  return c;
}

TEST(ParticleChunk, AppendKeepsEveryColumnInOrder) {
  const ParticleChunk first = Filled(3, 0), second = Filled(2, 3);
  ParticleChunk all;
  all.Append(first);
  all.Append(ParticleChunk{});
  all.Append(second);
  const ParticleChunk expected = Filled(5, 0);
  EXPECT_EQ(all.size(), 5u);
  EXPECT_EQ(all.position, expected.position);
  EXPECT_EQ(all.mass, expected.mass);
  EXPECT_EQ(all.id, expected.id);
  EXPECT_EQ(all.type, expected.type);
  EXPECT_EQ(all.smoothing, expected.smoothing);
  const auto got = VectorColumns(all);
  const auto want = VectorColumns(expected);
  for (std::size_t c = 0; c < got.size(); ++c) EXPECT_EQ(*got[c], *want[c]) << "vector column " << c;
}

TEST(ParticleChunk, AppendOfAChunkWithoutAColumnLeavesItAsItWas) {
  ParticleChunk all = Filled(2, 0);
  ParticleChunk bare;
  bare.position = {7, 8, 9};
  bare.mass = {1};
  bare.type = {0};
  all.Append(bare);
  EXPECT_EQ(all.size(), 3u);
  EXPECT_EQ(all.id.size(), 2u) << "no IDs appended";
  EXPECT_EQ(all.velocity.size(), 6u) << "no velocities appended";
  EXPECT_EQ(all.position.back(), 9);
}

}  // namespace
}  // namespace octocosm
