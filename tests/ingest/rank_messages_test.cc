// What ranks send one another (ingest/rank_messages.h) comes back exact,
// and a message cut short is an error, not a misread.
#include "ingest/rank_messages.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "base/error.h"

namespace octocosm {
namespace {

ParticleChunk RandomPoints(std::size_t n, const ParticleColumns& columns, unsigned seed) {
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  ParticleChunk points;
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) points.position.push_back(unit(random) * 1e5 + 1e-9 * unit(random));
    points.mass.push_back(unit(random));
    points.type.push_back(static_cast<std::uint8_t>(random() % 6));
    if (columns.id) points.id.push_back(random());
    if (columns.smoothing) points.smoothing.push_back(static_cast<float>(unit(random)));
    for (int k = 0; k < 3 && columns.vector(VectorColumn::kVelocity); ++k) {
      points.velocity.push_back(static_cast<float>(unit(random) - 0.5));
    }
  }
  return points;
}

TEST(RankMessages, PointSegmentsComeBackExactInOrder) {
  ParticleColumns columns;
  columns.id = true;
  columns.smoothing = true;
  columns.vector(VectorColumn::kVelocity) = true;
  const ParticleChunk points = RandomPoints(1000, columns, 7);
  const std::vector<std::uint32_t> odd = {1, 3, 5, 999}, none = {}, first = {0};
  Bytes message;
  AppendPointSegment(4, points, odd, columns, message);
  AppendPointSegment(9, points, none, columns, message);
  AppendPointSegment(2, points, first, columns, message);
  std::vector<std::uint32_t> tags;
  std::vector<ParticleChunk> got;
  ForEachPointSegment(message, columns, "test", [&](std::uint32_t tag, const ParticleChunk& segment) {
    tags.push_back(tag);
    got.push_back(segment);
  });
  ASSERT_EQ(tags, (std::vector<std::uint32_t>{4, 9, 2}));
  ASSERT_EQ(got[0].size(), 4u);
  EXPECT_EQ(got[1].size(), 0u);
  for (std::size_t k = 0; k < odd.size(); ++k) {
    const std::size_t i = odd[k];
    for (int c = 0; c < 3; ++c) EXPECT_EQ(got[0].position[3 * k + c], points.position[3 * i + c]);
    EXPECT_EQ(got[0].mass[k], points.mass[i]);
    EXPECT_EQ(got[0].type[k], points.type[i]);
    EXPECT_EQ(got[0].id[k], points.id[i]);
    EXPECT_EQ(got[0].smoothing[k], points.smoothing[i]);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(got[0].velocity[3 * k + c], points.velocity[3 * i + c]);
  }
  EXPECT_EQ(got[2].id[0], points.id[0]);
  // Cut short anywhere: an error naming what was read.
  for (std::size_t cut : {std::size_t{1}, std::size_t{13}, message.size() - 1}) {
    const Bytes short_message(message.begin(), message.begin() + static_cast<std::ptrdiff_t>(cut));
    EXPECT_THROW(ForEachPointSegment(short_message, columns, "test", [](std::uint32_t, const ParticleChunk&) {}), Error);
  }
}

TEST(RankMessages, NodesComeBackExact) {
  NodePoints node;
  node.position = {1.5, 2.25, 3.125, 1e-300, 7, 8};
  node.weight = {0.5, 0.25};
  node.smoothing = {0.1, 0.2};
  node.id = {42, 7};
  node.type = {1, 0};
  node.velocity = {1, 2, 3, 4, 5, 6};
  node.velocity_dispersion = {0.5f, 0.25f};
  node.shape = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  node.octant_offsets = {0, 1, 1, 1, 2, 2, 2, 2, 2};
  node.grid = {{1, 2, 3}, {4, 5, 6}};
  const NodeKey key = NodeKey::Root().Child(3).Child(5);
  const Bytes message = PackNode(key, node);
  NodeKey got_key;
  const NodePoints got = UnpackNode(message, got_key, "test");
  EXPECT_EQ(got_key, key);
  EXPECT_EQ(got.position, node.position);
  EXPECT_EQ(got.weight, node.weight);
  EXPECT_EQ(got.smoothing, node.smoothing);
  EXPECT_EQ(got.id, node.id);
  EXPECT_EQ(got.type, node.type);
  EXPECT_EQ(got.velocity, node.velocity);
  EXPECT_EQ(got.velocity_dispersion, node.velocity_dispersion);
  EXPECT_EQ(got.shape, node.shape);
  EXPECT_EQ(got.octant_offsets, node.octant_offsets);
  EXPECT_EQ(got.grid, node.grid);
  const Bytes short_message(message.begin(), message.end() - 1);
  EXPECT_THROW(UnpackNode(short_message, got_key, "test"), Error);
  Bytes long_message = message;
  long_message.push_back(0);
  EXPECT_THROW(UnpackNode(long_message, got_key, "test"), Error);
}

}  // namespace
}  // namespace octocosm
