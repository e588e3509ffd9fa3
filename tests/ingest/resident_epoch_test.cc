// The resident epoch (ingest/resident_epoch.h): columns kept narrow
// while their values fit, widened once when one does not, and every point
// read back exactly as it was appended, whichever form its columns took.
#include "ingest/resident_epoch.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <numeric>
#include <random>

#include "base/error.h"
#include "tests/support/temp_dir.h"

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

// Smoothing lengths, when the epoch carries them, are kept as appended and
// copied with their points; an epoch without them empties a stale column.
TEST(ResidentEpoch, KeepsAndCopiesSmoothingLengths) {
  ResidentEpoch epoch;
  ParticleColumns columns = WithIdAndVelocity();
  columns.smoothing = true;
  const std::vector<PageWarmer::Range> fresh = epoch.Reserve(300, columns);
  std::size_t reserved = 0;
  for (const PageWarmer::Range& range : fresh) reserved += range.bytes;
  EXPECT_EQ(reserved, 300u * (12 + 1 + 4 + 4 + 12)) << "positions, types, IDs, smoothing and velocities";
  ParticleChunk batch = NarrowBatch(300, 1);
  for (std::size_t i = 0; i < batch.size(); ++i) batch.smoothing.push_back(i % 4 == 0 ? 0.0f : 0.5f + static_cast<float>(i));
  epoch.Append(batch);
  EXPECT_EQ(epoch.BytesPerPoint(), 12u + 1 + 4 + 4 + 12);
  const std::vector<std::uint32_t> listed = {250, 3, 77, 4};
  const std::vector<std::uint32_t> target = {2, 0, 3, 1};
  ParticleChunk to;
  epoch.CopyPoints(listed, target, to);
  ASSERT_EQ(to.smoothing.size(), 4u);
  for (std::size_t k = 0; k < listed.size(); ++k) {
    EXPECT_EQ(to.smoothing[target[k]], batch.smoothing[listed[k]]);
    EXPECT_EQ(to.id[target[k]], batch.id[listed[k]]);
  }
  ParticleChunk without_smoothing = NarrowBatch(10, 1);
  EXPECT_THROW(epoch.Append(without_smoothing), Error);

  ResidentEpoch plain;
  plain.Reserve(10, WithIdAndVelocity());
  plain.Append(NarrowBatch(10, 1));
  to.smoothing.assign(4, 1.0f);
  plain.CopyPoints(std::vector<std::uint32_t>{1, 2}, std::vector<std::uint32_t>{0, 1}, to);
  EXPECT_TRUE(to.smoothing.empty());
  EXPECT_THROW(plain.Append(batch), Error) << "a batch with smoothing lengths the epoch was not reserved for";
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

// One run of particles for a file written by WriteSegments.
struct SegmentValues {
  int type;
  double mass;
  ParticleChunk points;  // positions exactly floats, velocities, IDs
  std::size_t id_bytes;
};

// Writes `lead` junk bytes, then for each segment its positions, velocities
// and IDs as plain little-endian arrays, and returns the segments as a
// source's MappableSegments would list them, file `file`.
std::vector<MappableSegment> WriteSegments(const std::string& path, std::size_t file, std::size_t lead,
                                           const std::vector<SegmentValues>& segments) {
  std::string bytes(lead, 'j');
  const auto put = [&bytes](const void* data, std::size_t size) {
    bytes.append(static_cast<const char*>(data), size);
  };
  std::vector<MappableSegment> listed;
  for (const SegmentValues& s : segments) {
    MappableSegment m{file, s.type, s.points.size(), s.mass, 0, 0, 0, s.id_bytes};
    m.position_offset = bytes.size();
    for (const double x : s.points.position) {
      const auto f = static_cast<float>(x);
      put(&f, 4);
    }
    m.velocity_offset = bytes.size();
    put(s.points.velocity.data(), 4 * s.points.velocity.size());
    m.id_offset = bytes.size();
    for (const std::uint64_t id : s.points.id) put(&id, s.id_bytes);  // little-endian: the low bytes
    listed.push_back(m);
  }
  std::ofstream(path, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return listed;
}

// A batch of `n` points all of one type and mass.
ParticleChunk OfType(std::size_t n, std::uint64_t first, int type, double mass) {
  ParticleChunk batch = NarrowBatch(n, first);
  for (std::size_t i = 0; i < n; ++i) {
    batch.type[i] = static_cast<std::uint8_t>(type);
    batch.mass[i] = mass;
  }
  return batch;
}

class MappedEpochTest : public ::testing::Test {
 protected:
  MappedEpochTest() {
    // File 0: two runs of types 1 and 2 after 6 bytes of header (8-byte IDs
    // off their alignment); file 1: a run of type 1 that starts past a page.
    values_ = {{1, 0.25, OfType(700, 1, 1, 0.25), 8},
               {2, 3.5, OfType(300, 5001, 2, 3.5), 4},
               {1, 0.25, OfType(500, std::uint64_t{1} << 40, 1, 0.25), 8}};
    segments_ = WriteSegments(Path(0), 0, 6, {values_[0], values_[1]});
    for (const MappableSegment& s : WriteSegments(Path(1), 1, 5000, {values_[2]})) segments_.push_back(s);
    for (const SegmentValues& v : values_) AppendTo(all_, v.points);
  }
  std::string Path(int file) const { return (dir_.path() / ("file." + std::to_string(file))).string(); }
  std::vector<std::string> Files() const { return {Path(0), Path(1)}; }

  testing_support::TempDir dir_{"resident-epoch-test"};
  std::vector<SegmentValues> values_;
  std::vector<MappableSegment> segments_;
  ParticleChunk all_;
};

TEST_F(MappedEpochTest, ReadsEveryPointWhereItLiesInItsFile) {
  ResidentEpoch epoch;
  ASSERT_TRUE(epoch.Map(segments_, Files(), WithIdAndVelocity()));
  EXPECT_TRUE(epoch.mapped());
  ASSERT_EQ(epoch.size(), 1500u);
  EXPECT_TRUE(epoch.masses_per_type());
  EXPECT_FALSE(epoch.ids_narrow());
  ExpectSame(Whole(epoch), all_);
  for (std::size_t i : {0u, 699u, 700u, 999u, 1000u, 1499u}) {
    const std::array<double, 3> p = epoch.Position(i);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(p[static_cast<std::size_t>(a)], all_.position[3 * i + a]) << i;
    float x;
    std::memcpy(&x, epoch.PositionAddress(i), sizeof x);
    EXPECT_EQ(x, all_.position[3 * i]) << i;
  }
  // Listed across the runs and back, as merged chunks list them.
  const std::vector<std::uint32_t> listed = {1200, 5, 850, 699, 1000, 700, 3};
  const std::vector<std::uint32_t> target = {6, 0, 3, 1, 5, 2, 4};
  ParticleChunk to;
  epoch.CopyPoints(listed, target, to);
  ASSERT_EQ(to.size(), listed.size());
  for (std::size_t k = 0; k < listed.size(); ++k) {
    const std::size_t i = listed[k], j = target[k];
    EXPECT_EQ(to.id[j], all_.id[i]);
    EXPECT_EQ(to.mass[j], all_.mass[i]);
    EXPECT_EQ(to.type[j], all_.type[i]);
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(to.position[3 * j + a], all_.position[3 * i + a]);
      EXPECT_EQ(to.velocity[3 * j + a], all_.velocity[3 * i + a]);
    }
  }
  std::vector<std::uint64_t> ids;
  epoch.VisitIds([&ids](std::span<const std::uint64_t> batch) { ids.insert(ids.end(), batch.begin(), batch.end()); });
  EXPECT_EQ(ids, all_.id);
  EXPECT_THROW(epoch.Append(NarrowBatch(1, 1)), Error);
}

TEST_F(MappedEpochTest, RefusesWhatItCannotMapAndIsLeftEmpty) {
  const auto refused = [this](std::vector<MappableSegment> segments, std::vector<std::string> files,
                              const ParticleColumns& columns) {
    ResidentEpoch epoch;
    if (epoch.Map(segments, files, columns)) return false;
    EXPECT_EQ(epoch.size(), 0u);
    EXPECT_FALSE(epoch.mapped());
    return true;
  };
  ASSERT_FALSE(refused(segments_, Files(), WithIdAndVelocity()));
  std::vector<MappableSegment> longer = segments_;
  longer.back().count += 1;
  EXPECT_TRUE(refused(longer, Files(), WithIdAndVelocity())) << "past the end of file 1";
  std::vector<MappableSegment> heavier = segments_;
  heavier.back().mass = 0.5;
  EXPECT_TRUE(refused(heavier, Files(), WithIdAndVelocity())) << "type 1 weighs 0.25 in file 0";
  EXPECT_TRUE(refused(segments_, {Path(0), Path(7)}, WithIdAndVelocity())) << "no such file";
  EXPECT_TRUE(refused(segments_, {Path(0)}, WithIdAndVelocity())) << "no file 1";
  ParticleColumns joined = WithIdAndVelocity();
  joined.vector(VectorColumn::kDisplacement) = true;
  EXPECT_TRUE(refused(segments_, Files(), joined)) << "displacements are not in the files";
  ParticleColumns smoothed = WithIdAndVelocity();
  smoothed.smoothing = true;
  EXPECT_TRUE(refused(segments_, Files(), smoothed)) << "smoothing lengths are not in the segments";
  EXPECT_TRUE(refused({}, Files(), WithIdAndVelocity()));
}

TEST_F(MappedEpochTest, ValuesAreAsReadOnlyWhenFiniteAndInsideAPeriodicBox) {
  const Cube box{{0, 0, 0}, 100, true};
  const Cube open{{0, 0, 0}, 100, false};
  const auto as_read = [this](const std::vector<SegmentValues>& second_file, const Cube& cube) {
    WriteSegments(Path(1), 1, 5000, second_file);
    ResidentEpoch epoch;
    EXPECT_TRUE(epoch.Map(segments_, Files(), WithIdAndVelocity()));
    std::size_t checked = 0;
    const bool usable = epoch.ValuesAsRead(cube, 2, [&checked](std::size_t n) { checked += n; });
    if (usable) {
      EXPECT_EQ(checked, epoch.size());
    }
    return usable;
  };
  EXPECT_TRUE(as_read({values_[2]}, box));
  std::vector<SegmentValues> changed = {values_[2]};
  changed[0].points.position[3 * 499 + 2] = 100;  // on the box's far face: wrapped to 0 by a read
  EXPECT_FALSE(as_read(changed, box));
  EXPECT_TRUE(as_read(changed, open));
  changed[0].points.position[3 * 499 + 2] = -1e-3;
  EXPECT_FALSE(as_read(changed, box));
  changed[0].points.position[3 * 499 + 2] = NAN;
  EXPECT_FALSE(as_read(changed, open));
  changed = {values_[2]};
  changed[0].points.velocity[3 * 250] = INFINITY;
  EXPECT_FALSE(as_read(changed, open));
}

}  // namespace
}  // namespace octocosm
