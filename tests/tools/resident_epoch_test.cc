// The resident epoch (tools/ingest/resident_epoch.h): columns kept narrow
// while their values fit, widened once when one does not, and every point
// read back exactly as it was appended, whichever form its columns took.
#include "tools/ingest/resident_epoch.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <numeric>
#include <random>

#include "storage/error.h"

namespace octocosm {
namespace {

ParticleColumns WithIdAndVelocity() {
  ParticleColumns columns;
  columns.id = true;
  columns.vector(VectorColumn::kVelocity) = true;
  return columns;
}

// `n` points whose positions are floats, whose mass is one per type (types
// 0..2) and whose IDs fit in 32 bits, numbered from `first` so that batches
// differ.
ParticleChunk NarrowBatch(std::size_t n, std::uint64_t first) {
  std::mt19937_64 rng(first);
  std::uniform_real_distribution<float> anywhere(0, 100);
  ParticleChunk batch;
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) batch.position.push_back(anywhere(rng));
    const std::uint8_t type = static_cast<std::uint8_t>((first + i) % 3);
    batch.type.push_back(type);
    batch.mass.push_back(0.25 + type);
    batch.id.push_back(first + i);
    for (int a = 0; a < 3; ++a) batch.velocity.push_back(static_cast<float>(first + i) + static_cast<float>(a) / 4);
  }
  return batch;
}

void AppendTo(ParticleChunk& all, const ParticleChunk& batch) {
  const auto append = [](auto& to, const auto& from) { to.insert(to.end(), from.begin(), from.end()); };
  append(all.position, batch.position);
  append(all.mass, batch.mass);
  append(all.type, batch.type);
  append(all.id, batch.id);
  append(all.velocity, batch.velocity);
}

// Every point of `epoch`, in order, through CopyPoints.
ParticleChunk Whole(const ResidentEpoch& epoch) {
  std::vector<std::uint32_t> every(epoch.size());
  std::iota(every.begin(), every.end(), 0u);
  ParticleChunk all;
  epoch.CopyPoints(every, every, all);
  return all;
}

void ExpectSame(const ParticleChunk& actual, const ParticleChunk& expected) {
  EXPECT_EQ(actual.position, expected.position);
  EXPECT_EQ(actual.mass, expected.mass);
  EXPECT_EQ(actual.type, expected.type);
  EXPECT_EQ(actual.id, expected.id);
  EXPECT_EQ(actual.velocity, expected.velocity);
}

TEST(ResidentEpoch, KeepsColumnsNarrowWhileTheirValuesFit) {
  ResidentEpoch epoch;
  const std::vector<PageWarmer::Range> fresh = epoch.Reserve(3000, WithIdAndVelocity());
  std::size_t reserved = 0;
  for (const PageWarmer::Range& range : fresh) reserved += range.bytes;
  EXPECT_EQ(reserved, 3000u * (12 + 1 + 4 + 12)) << "positions, types, IDs and velocities, narrow; no masses";
  ParticleChunk expected;
  for (std::uint64_t first : {1, 1001, 2001}) {
    const ParticleChunk batch = NarrowBatch(1000, first);
    epoch.Append(batch);
    AppendTo(expected, batch);
  }
  EXPECT_TRUE(epoch.positions_narrow());
  EXPECT_TRUE(epoch.masses_per_type());
  EXPECT_TRUE(epoch.ids_narrow());
  EXPECT_EQ(epoch.BytesPerPoint(), 12u + 1 + 4 + 12);
  ASSERT_EQ(epoch.size(), 3000u);
  ExpectSame(Whole(epoch), expected);
  for (std::size_t i : {0u, 1234u, 2999u}) {
    const std::array<double, 3> p = epoch.Position(i);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(p[static_cast<std::size_t>(a)], expected.position[3 * i + a]);
  }
}

// Each column widens at the first batch with a value that does not fit,
// and the points before it keep their exact values.
TEST(ResidentEpoch, WidensAColumnWhenAValueNoLongerFits) {
  ResidentEpoch epoch;
  epoch.Reserve(100, WithIdAndVelocity());  // fewer than appended: the columns grow past it
  ParticleChunk expected;
  const auto append = [&](const ParticleChunk& batch) {
    epoch.Append(batch);
    AppendTo(expected, batch);
    ExpectSame(Whole(epoch), expected);
  };
  append(NarrowBatch(500, 1));

  ParticleChunk finer = NarrowBatch(500, 501);
  finer.position[7] = 12.1;  // not a float
  append(finer);
  EXPECT_FALSE(epoch.positions_narrow());
  EXPECT_TRUE(epoch.masses_per_type());

  ParticleChunk heavier = NarrowBatch(500, 1001);
  heavier.mass[250] *= 2;  // one particle of its type weighs more
  append(heavier);
  EXPECT_FALSE(epoch.masses_per_type());
  EXPECT_TRUE(epoch.ids_narrow());

  ParticleChunk large_ids = NarrowBatch(500, 1501);
  large_ids.id[499] = std::uint64_t{1} << 40;
  append(large_ids);
  EXPECT_FALSE(epoch.ids_narrow());
  EXPECT_EQ(epoch.BytesPerPoint(), 24u + 8 + 1 + 8 + 12);

  append(NarrowBatch(500, 2001));  // narrow values after widening stay exact too
  EXPECT_EQ(epoch.size(), 2500u);
}

// A coordinate beyond float's range (converting it would be undefined) and
// a mass that differs from its type's in the first batch widen as well.
TEST(ResidentEpoch, WidensForValuesOutOfFloatRangeAndWithinTheFirstBatch) {
  ResidentEpoch epoch;
  epoch.Reserve(10, WithIdAndVelocity());
  ParticleChunk batch = NarrowBatch(10, 3);
  batch.position[4] = 1e300;
  batch.mass[9] = 7.5;
  epoch.Append(batch);
  EXPECT_FALSE(epoch.positions_narrow());
  EXPECT_FALSE(epoch.masses_per_type());
  ExpectSame(Whole(epoch), batch);
}

TEST(ResidentEpoch, CopiesListedPointsToTheirTargetsAndEmptiesAbsentColumns) {
  ResidentEpoch epoch;
  ParticleColumns columns;  // no IDs, no velocities
  epoch.Reserve(200, columns);
  ParticleChunk batch = NarrowBatch(200, 11);
  batch.id.clear();
  batch.velocity.clear();
  epoch.Append(batch);
  ParticleChunk to = NarrowBatch(5, 900);  // stale columns of another chunk
  const std::vector<std::uint32_t> listed = {150, 3, 77};
  const std::vector<std::uint32_t> target = {2, 0, 1};
  epoch.CopyPoints(listed, target, to);
  ASSERT_EQ(to.size(), 3u);
  EXPECT_TRUE(to.id.empty());
  EXPECT_TRUE(to.velocity.empty());
  for (std::size_t k = 0; k < listed.size(); ++k) {
    const std::size_t i = listed[k], j = target[k];
    EXPECT_EQ(to.mass[j], batch.mass[i]);
    EXPECT_EQ(to.type[j], batch.type[i]);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(to.position[3 * j + a], batch.position[3 * i + a]);
  }
}

TEST(ResidentEpoch, RefusesABatchWithOtherColumns) {
  ResidentEpoch epoch;
  epoch.Reserve(10, WithIdAndVelocity());
  ParticleChunk without_velocity = NarrowBatch(10, 1);
  without_velocity.velocity.clear();
  EXPECT_THROW(epoch.Append(without_velocity), Error);
  ParticleChunk short_ids = NarrowBatch(10, 1);
  short_ids.id.pop_back();
  EXPECT_THROW(epoch.Append(short_ids), Error);
  ResidentEpoch without_ids;
  without_ids.Reserve(10, ParticleColumns{});
  EXPECT_THROW(without_ids.Append(NarrowBatch(10, 1)), Error);
  EXPECT_EQ(without_ids.size(), 0u);
}

}  // namespace
}  // namespace octocosm
