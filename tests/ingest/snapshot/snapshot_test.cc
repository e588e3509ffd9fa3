// Reads every real snapshot in ../shared/data (see its README.txt) and checks
// counts, IDs, masses, bounds and header values against what the README
// documents about each file. Skipped when the folder is absent.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numeric>
#include <set>

#include <gtest/gtest.h>

#include "base/error.h"
#include "ingest/snapshot/snapshot_source.h"
#include "tests/ingest/snapshot/snapshot_test_util.h"

namespace octocosm {
namespace {

const std::string kData = OCTOCOSM_SHARED_DATA;

std::string DataFile(const std::string& name) { return kData + "/" + name; }

class SharedDataTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!std::filesystem::is_directory(kData)) GTEST_SKIP() << "no shared data folder at " << kData;
  }
};

struct Bounds {
  double lo[3] = {INFINITY, INFINITY, INFINITY};
  double hi[3] = {-INFINITY, -INFINITY, -INFINITY};
};

Bounds BoundsOf(const ParticleChunk& particles) {
  Bounds b;
  for (std::size_t i = 0; i < particles.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      b.lo[k] = std::min(b.lo[k], particles.position[3 * i + k]);
      b.hi[k] = std::max(b.hi[k], particles.position[3 * i + k]);
    }
  }
  return b;
}

// Checks that the IDs are exactly first..last, each once.
void ExpectIdRange(std::vector<std::uint64_t> ids, std::uint64_t first, std::uint64_t last) {
  ASSERT_EQ(ids.size(), last - first + 1);
  std::sort(ids.begin(), ids.end());
  EXPECT_EQ(ids.front(), first);
  EXPECT_EQ(ids.back(), last);
  EXPECT_EQ(std::adjacent_find(ids.begin(), ids.end()), ids.end()) << "duplicate IDs";
}

std::vector<std::uint64_t> IdsOfType(const ParticleChunk& particles, int type) {
  std::vector<std::uint64_t> ids;
  for (std::size_t i = 0; i < particles.size(); ++i) {
    if (particles.type[i] == type) ids.push_back(particles.id[i]);
  }
  return ids;
}

TEST_F(SharedDataTest, LcdmLittleEndianHeaderAndParticles) {
  auto source = OpenSnapshot(DataFile("gadget2_ics/lcdm_gas_littleendian.dat"), {});
  const SnapshotHeader& h = source->header();
  EXPECT_EQ(h.format, "gadget1");
  EXPECT_EQ(h.files.size(), 1u);
  EXPECT_EQ(h.count_per_type, (std::vector<std::uint64_t>{32768, 32768, 0, 0, 0, 0}));
  EXPECT_EQ(h.total_count, 65536u);
  EXPECT_NEAR(h.time, 0.0909091, 1e-6);
  EXPECT_DOUBLE_EQ(h.redshift, 10.0);
  EXPECT_TRUE(h.cosmological);
  EXPECT_EQ(h.box_size, 0.0);  // the header really says 0 (the box is only in the .param file)
  EXPECT_TRUE(h.has_velocity);
  EXPECT_TRUE(h.has_id);
  EXPECT_EQ(h.extra["flags"]["cooling"], 424242);
  EXPECT_EQ(h.extra["byte_order"], "little-endian");
  EXPECT_EQ(h.extra["num_files_in_header"], 0);

  ParticleChunk all = ReadAll(*source);
  ASSERT_EQ(all.size(), 65536u);
  ExpectIdRange(all.id, 1, 65536);
  ExpectIdRange(IdsOfType(all, 0), 1, 32768);
  ExpectIdRange(IdsOfType(all, 1), 32769, 65536);
  for (std::size_t i = 0; i < all.size(); ++i) {
    ASSERT_DOUBLE_EQ(all.mass[i], all.type[i] == 0 ? 4.235076384894417 : 27.52799650181371) << i;
  }
  // The README's "[0.41, 49999.4]" is the dark matter's x range; over all
  // particles and axes the minimum is a gas z of 0.1016 (checked independently
  // with a Python struct decode of the same file).
  Bounds b = BoundsOf(all);
  for (int k = 0; k < 3; ++k) {
    EXPECT_GT(b.lo[k], 0.0);
    EXPECT_LT(b.hi[k], 50000.0);
  }
  EXPECT_NEAR(*std::min_element(b.lo, b.lo + 3), 0.1016, 1e-4);
  EXPECT_NEAR(*std::max_element(b.hi, b.hi + 3), 49999.4, 0.1);
}

TEST_F(SharedDataTest, BigAndLittleEndianLcdmGiveIdenticalParticles) {
  auto little = OpenSnapshot(DataFile("gadget2_ics/lcdm_gas_littleendian.dat"), {});
  auto big = OpenSnapshot(DataFile("gadget2_ics/lcdm_gas_bigendian.dat"), {});
  EXPECT_EQ(big->header().extra["byte_order"], "big-endian");
  EXPECT_EQ(big->header().count_per_type, little->header().count_per_type);
  EXPECT_EQ(big->header().time, little->header().time);
  ParticleChunk a = ReadAll(*little), b = ReadAll(*big);
  EXPECT_EQ(a.size(), 65536u);
  EXPECT_TRUE(SameParticles(a, b));
}

TEST_F(SharedDataTest, GalaxyIcHasTableMassesAndDocumentedBounds) {
  auto source = OpenSnapshot(DataFile("gadget2_ics/galaxy_littleendian.dat"), {});
  const SnapshotHeader& h = source->header();
  EXPECT_EQ(h.count_per_type, (std::vector<std::uint64_t>{0, 40000, 20000, 0, 0, 0}));
  EXPECT_EQ(h.time, 0.0);
  EXPECT_FALSE(h.cosmological);
  EXPECT_EQ(h.box_size, 0.0);
  ParticleChunk all = ReadAll(*source);
  ExpectIdRange(all.id, 1, 60000);
  for (std::size_t i = 0; i < all.size(); ++i) {
    ASSERT_DOUBLE_EQ(all.mass[i], all.type[i] == 1 ? 0.0010463387006893754 : 0.00023251971288118511);
  }
  Bounds b = BoundsOf(all);
  const double lo[3] = {-191.4, -133.1, -99.4}, hi[3] = {192.3, 131.8, 99.1};
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(b.lo[k], lo[k], 0.06) << k;
    EXPECT_NEAR(b.hi[k], hi[k], 0.06) << k;
  }
}

TEST_F(SharedDataTest, GasSphereFallsBackToFileCountsAndReadsMassBlock) {
  auto source = OpenSnapshot(DataFile("gadget2_ics/gassphere_littleendian.dat"), {});
  const SnapshotHeader& h = source->header();
  EXPECT_EQ(h.count_per_type, (std::vector<std::uint64_t>{1472, 0, 0, 0, 0, 0}));
  EXPECT_EQ(h.extra["totals_from_file_counts"], true);
  ParticleChunk all = ReadAll(*source);
  ExpectIdRange(all.id, 1, 1472);
  // MassTable is all zero, so every mass comes from the MASS block: 1/1472 each.
  double total = std::accumulate(all.mass.begin(), all.mass.end(), 0.0);
  EXPECT_NEAR(total, 1.0, 1e-6);
  for (double m : all.mass) ASSERT_NEAR(m, 1.0 / 1472, 1e-9);
  for (float v : all.velocity) ASSERT_EQ(v, 0.0f);
  Bounds b = BoundsOf(all);
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(b.lo[k], -0.927, 0.001);
    EXPECT_NEAR(b.hi[k], 0.927, 0.001);
  }
}

TEST_F(SharedDataTest, Format2TwoFileSnapshotByBaseNameAndByMember) {
  for (const char* name : {"test_g2_snap", "test_g2_snap.1", "test_g2_snap.0"}) {
    SCOPED_TRACE(name);
    auto source = OpenSnapshot(DataFile(std::string("gadget2_format2_multifile/") + name), {});
    const SnapshotHeader& h = source->header();
    EXPECT_EQ(h.format, "gadget2");
    ASSERT_EQ(h.files.size(), 2u);
    EXPECT_EQ(h.files[0], DataFile("gadget2_format2_multifile/test_g2_snap.0"));
    EXPECT_EQ(h.files[1], DataFile("gadget2_format2_multifile/test_g2_snap.1"));
    EXPECT_EQ(h.count_per_type, (std::vector<std::uint64_t>{4039, 4096, 0, 0, 57, 0}));
    EXPECT_EQ(h.total_count, 8192u);
    EXPECT_NEAR(h.time, 0.2777778, 1e-6);
    EXPECT_NEAR(h.redshift, 2.6, 1e-6);
    EXPECT_EQ(h.box_size, 3000.0);
    EXPECT_EQ(h.omega0, 0.2669);
    EXPECT_EQ(h.omega_lambda, 0.7331);
    EXPECT_EQ(h.hubble_param, 0.71);
    EXPECT_TRUE(h.cosmological);
    // The junk high word of type 2 must be noticed and ignored, not trusted.
    EXPECT_EQ(h.extra["ignored_total_high_words"]["2"], 228);

    ParticleChunk all = ReadAll(*source);
    ASSERT_EQ(all.size(), 8192u);
    ExpectIdRange(all.id, 1, 8192);
    for (std::size_t i = 0; i < all.size(); ++i) {
      // Type 1 from the mass table, gas and stars from the MASS block.
      double expected = all.type[i] == 1 ? 0.0406160778174934 : 0.008214693516492844;
      ASSERT_NEAR(all.mass[i], expected, 1e-12) << "type " << int(all.type[i]);
      for (int k = 0; k < 3; ++k) {
        ASSERT_GE(all.position[3 * i + k], 0.1);
        ASSERT_LT(all.position[3 * i + k], 3000.0);
      }
    }
    // Particles come file by file: the 4083 of file .0 first, all with z below
    // 1500.2 (as the README rounds it; the largest is 1500.2229).
    for (std::size_t i = 0; i < 4083; ++i) ASSERT_LT(all.position[3 * i + 2], 1500.23);
  }
}

// The HSML block of the format 2 pair, as raw floats, file after file (one
// per gas particle): read here from the bytes, apart from the reader.
std::vector<float> RawHsmlBlocks() {
  std::vector<float> values;
  for (const char* name : {"test_g2_snap.0", "test_g2_snap.1"}) {
    std::ifstream in(DataFile(std::string("gadget2_format2_multifile/") + name), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    bool found = false;
    // Every block: [int32 8]["NAME"][int32 n + 8][int32 8] [int32 n][n bytes][int32 n], little-endian.
    for (std::size_t offset = 0; offset + 20 <= bytes.size();) {
      std::uint32_t n = 0;
      std::memcpy(&n, bytes.data() + offset + 16, 4);
      if (bytes.compare(offset + 4, 4, "HSML") == 0) {
        for (std::size_t i = 0; i < n / 4; ++i) {
          float h;
          std::memcpy(&h, bytes.data() + offset + 20 + 4 * i, 4);
          values.push_back(h);
        }
        found = true;
      }
      offset += 20 + std::size_t{n} + 4;
    }
    EXPECT_TRUE(found) << name;
  }
  return values;
}

// GADGET-2 wrote the gas particles' smoothing lengths into the HSML block:
// each gas particle gets its own, positive and finite, and the dark matter
// and stars get 0 ("not given").
TEST_F(SharedDataTest, Format2HsmlBlockGivesTheGasTheirSmoothingLengths) {
  static_assert(std::endian::native == std::endian::little, "the raw block is decoded in this machine's order");
  const std::vector<float> raw = RawHsmlBlocks();
  ASSERT_EQ(raw.size(), 4039u);
  auto source = OpenSnapshot(DataFile("gadget2_format2_multifile/test_g2_snap"), {});
  EXPECT_TRUE(source->header().has_smoothing);
  const ParticleChunk all = ReadAll(*source);
  ASSERT_EQ(all.smoothing.size(), 8192u);
  std::size_t gas = 0;
  for (std::size_t i = 0; i < all.size(); ++i) {
    if (all.type[i] != 0) {
      ASSERT_EQ(all.smoothing[i], 0.0f) << "type " << int(all.type[i]) << " ID " << all.id[i];
      continue;
    }
    ASSERT_TRUE(std::isfinite(all.smoothing[i]) && all.smoothing[i] > 0) << "ID " << all.id[i];
    ASSERT_EQ(all.smoothing[i], raw[gas]) << "gas particle " << gas << ", ID " << all.id[i];
    ++gas;
  }
  EXPECT_EQ(gas, 4039u);
  // Tens to hundreds of kpc/h in the 3000 kpc/h box: lengths, not junk bytes.
  EXPECT_GT(*std::min_element(raw.begin(), raw.end()), 30.0f);
  EXPECT_LT(*std::max_element(raw.begin(), raw.end()), 700.0f);

  ReadOptions without;
  without.read_smoothing = false;
  auto plain = OpenSnapshot(DataFile("gadget2_format2_multifile/test_g2_snap"), without);
  EXPECT_FALSE(plain->header().has_smoothing);
  EXPECT_TRUE(ReadAll(*plain).smoothing.empty());
}

TEST_F(SharedDataTest, AllHdf5SnapshotsOfTheTimeSeries) {
  std::vector<std::uint64_t> reference_ids;
  for (int i = 0; i <= 20; ++i) {
    char name[64];
    std::snprintf(name, sizeof name, "gadget4_hdf5_galaxy_collision_timeseries/snapshot_%03d.hdf5", i);
    SCOPED_TRACE(name);
    auto source = OpenSnapshot(DataFile(name), {});
    const SnapshotHeader& h = source->header();
    EXPECT_EQ(h.format, "hdf5-gadget");
    EXPECT_EQ(h.files.size(), 1u);
    EXPECT_EQ(h.count_per_type, (std::vector<std::uint64_t>{0, 40000, 20000}));
    EXPECT_EQ(h.extra["ntypes"], 3);
    EXPECT_NEAR(h.time, 0.5 * i, 0.01);
    EXPECT_EQ(h.redshift, 0.0);
    EXPECT_EQ(h.box_size, 0.0);
    EXPECT_FALSE(h.cosmological);
    EXPECT_EQ(h.extra["comoving_integration"], 0);
    EXPECT_TRUE(h.has_velocity);
    ParticleChunk all = ReadAll(*source);
    ASSERT_EQ(all.size(), 60000u);
    ExpectIdRange(IdsOfType(all, 1), 1, 40000);
    ExpectIdRange(IdsOfType(all, 2), 40001, 60000);
    for (std::size_t p = 0; p < all.size(); ++p) {
      ASSERT_NEAR(all.mass[p], all.type[p] == 1 ? 0.00104634 : 0.00023252, 1e-8);
    }
    std::vector<std::uint64_t> ids = all.id;
    std::sort(ids.begin(), ids.end());
    if (i == 0) reference_ids = ids;
    EXPECT_EQ(ids, reference_ids) << "the same particle set in every snapshot";

    Bounds b = BoundsOf(all);
    const double documented[3][2][3] = {{{-191, -133, -99}, {192, 132, 99}},
                                        {{-862, -690, -599}, {926, 704, 550}},
                                        {{-1844, -1411, -1248}, {1981, 1449, 1142}}};
    if (i % 10 == 0) {
      for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(b.lo[k], documented[i / 10][0][k], 1.0) << "axis " << k;
        EXPECT_NEAR(b.hi[k], documented[i / 10][1][k], 1.0) << "axis " << k;
      }
    }
  }
}

TEST_F(SharedDataTest, Hdf5SnapshotZeroEqualsTheGadgetIcItStartedFrom) {
  auto ic = OpenSnapshot(DataFile("gadget2_ics/galaxy_littleendian.dat"), {});
  auto hdf5 = OpenSnapshot(DataFile("gadget4_hdf5_galaxy_collision_timeseries/snapshot_000.hdf5"), {});
  ParticleChunk a = ReadAll(*ic), b = ReadAll(*hdf5);
  ASSERT_EQ(a.size(), b.size());
  // Both list type 1 then type 2; compare positions particle by particle, by ID.
  std::vector<std::size_t> order_a(a.size()), order_b(b.size());
  std::iota(order_a.begin(), order_a.end(), 0);
  std::iota(order_b.begin(), order_b.end(), 0);
  std::sort(order_a.begin(), order_a.end(), [&](auto x, auto y) { return a.id[x] < a.id[y]; });
  std::sort(order_b.begin(), order_b.end(), [&](auto x, auto y) { return b.id[x] < b.id[y]; });
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_NEAR(a.position[3 * order_a[i] + k], b.position[3 * order_b[i] + k], 1e-3) << "ID " << a.id[order_a[i]];
    }
  }
}

class ChunkingTest : public SharedDataTest, public ::testing::WithParamInterface<const char*> {};

TEST_P(ChunkingTest, TinyChunksGiveTheSameDataAndRewindRepeats) {
  ReadOptions big;
  auto whole = OpenSnapshot(DataFile(GetParam()), big);
  std::size_t chunks = 0;
  ParticleChunk reference = ReadAll(*whole, &chunks);
  EXPECT_EQ(chunks, 1u);
  ASSERT_EQ(reference.size(), whole->header().total_count);

  for (std::size_t chunk_particles : {std::size_t{1000}, std::size_t{4093}}) {
    ReadOptions small;
    small.chunk_particles = chunk_particles;
    auto source = OpenSnapshot(DataFile(GetParam()), small);
    ParticleChunk first = ReadAll(*source, &chunks);
    EXPECT_EQ(chunks, (reference.size() + chunk_particles - 1) / chunk_particles);
    EXPECT_TRUE(SameParticles(first, reference)) << chunk_particles;
    source->Rewind();
    EXPECT_TRUE(SameParticles(ReadAll(*source), reference)) << "after Rewind";
  }
  // Rewinding part-way through also starts over.
  ReadOptions small;
  small.chunk_particles = 777;
  auto source = OpenSnapshot(DataFile(GetParam()), small);
  ParticleChunk chunk;
  ASSERT_TRUE(source->Next(chunk));
  ASSERT_TRUE(source->Next(chunk));
  source->Rewind();
  EXPECT_TRUE(SameParticles(ReadAll(*source), reference));
}

INSTANTIATE_TEST_SUITE_P(AllFormats, ChunkingTest,
                         ::testing::Values("gadget2_ics/lcdm_gas_bigendian.dat", "gadget2_ics/gassphere_littleendian.dat",
                                           "gadget2_format2_multifile/test_g2_snap",
                                           "gadget4_hdf5_galaxy_collision_timeseries/snapshot_007.hdf5"));

TEST_F(SharedDataTest, TypeSelectionReadsOnlyTheChosenTypes) {
  auto everything = OpenSnapshot(DataFile("gadget2_format2_multifile/test_g2_snap"), {});
  ParticleChunk all = ReadAll(*everything);
  ReadOptions stars;
  stars.types = {4};
  auto source = OpenSnapshot(DataFile("gadget2_format2_multifile/test_g2_snap"), stars);
  EXPECT_EQ(source->header().count_per_type, (std::vector<std::uint64_t>{0, 0, 0, 0, 57, 0}));
  EXPECT_EQ(source->header().total_count, 57u);
  ParticleChunk only = ReadAll(*source);
  ParticleChunk expected;
  for (std::size_t i = 0; i < all.size(); ++i) {
    if (all.type[i] != 4) continue;
    expected.position.insert(expected.position.end(), &all.position[3 * i], &all.position[3 * i] + 3);
    expected.velocity.insert(expected.velocity.end(), &all.velocity[3 * i], &all.velocity[3 * i] + 3);
    expected.mass.push_back(all.mass[i]);
    expected.id.push_back(all.id[i]);
    expected.type.push_back(4);
  }
  EXPECT_TRUE(SameParticles(only, expected));

  ReadOptions disk;
  disk.types = {2};
  disk.read_velocity = false;
  disk.read_id = false;
  auto hdf5 = OpenSnapshot(DataFile("gadget4_hdf5_galaxy_collision_timeseries/snapshot_020.hdf5"), disk);
  EXPECT_EQ(hdf5->header().count_per_type, (std::vector<std::uint64_t>{0, 0, 20000}));
  EXPECT_FALSE(hdf5->header().has_velocity);
  EXPECT_FALSE(hdf5->header().has_id);
  ParticleChunk disk_particles = ReadAll(*hdf5);
  EXPECT_EQ(disk_particles.size(), 20000u);
  EXPECT_TRUE(std::all_of(disk_particles.type.begin(), disk_particles.type.end(), [](auto t) { return t == 2; }));
}

TEST_F(SharedDataTest, BoxSizeOverrideReplacesTheZeroBoxOfIcs) {
  ReadOptions options;
  options.box_size_override = 50000;
  auto source = OpenSnapshot(DataFile("gadget2_ics/lcdm_gas_littleendian.dat"), options);
  EXPECT_EQ(source->header().box_size, 50000.0);
}

// Every prefix of a real file must either read or fail with BadInput; under
// ASan/UBSan this is the check that no truncation makes the readers misbehave.
void SweepTruncations(const std::string& source_path, const std::vector<std::string>& companions,
                      std::uint64_t stride) {
  ScratchDir dir;
  std::string name = std::filesystem::path(source_path).filename().string();
  for (const std::string& companion : companions) {
    std::filesystem::copy_file(companion, dir.File(std::filesystem::path(companion).filename().string()));
  }
  std::ifstream in(source_path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<std::uint64_t> lengths;
  for (std::uint64_t n = 0; n < bytes.size(); n += stride) lengths.push_back(n);
  for (std::uint64_t n = 1; n < 300; ++n) lengths.push_back(n);
  for (std::uint64_t back = 1; back < 12; ++back) lengths.push_back(bytes.size() - back);
  std::size_t failures = 0;
  for (std::uint64_t n : lengths) {
    {
      std::ofstream out(dir.File(name), std::ios::binary | std::ios::trunc);
      out.write(bytes.data(), static_cast<std::streamsize>(n));
    }
    try {
      ReadOptions options;
      options.chunk_particles = 5000;
      auto source = OpenSnapshot(dir.File(name), options);
      ReadAll(*source);
    } catch (const Error& error) {
      ++failures;
      ASSERT_EQ(error.kind(), ErrorKind::kBadInput) << n << ": " << error.what();
      ASSERT_NE(std::string(error.what()).find(name), std::string::npos) << error.what();
    }
  }
  // Only cuts exactly at a record boundary can leave a readable file.
  EXPECT_GE(failures, lengths.size() - 6);
}

TEST_F(SharedDataTest, TruncatedGadgetFilesFailCleanly) {
  SweepTruncations(DataFile("gadget2_ics/gassphere_littleendian.dat"), {}, 97);
  SweepTruncations(DataFile("gadget2_ics/lcdm_gas_bigendian.dat"), {}, 65521);
  SweepTruncations(DataFile("gadget2_format2_multifile/test_g2_snap.0"),
                   {DataFile("gadget2_format2_multifile/test_g2_snap.1")}, 4099);
}

TEST_F(SharedDataTest, DamagedGadgetHeaderBytesFailCleanly) {
  // Every byte of the header record (and the first POS marker) set to 0xff or
  // 0x7f in turn: the read must succeed or fail with BadInput, never crash.
  ScratchDir dir;
  std::ifstream in(DataFile("gadget2_ics/gassphere_littleendian.dat"), std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string path = dir.File("damaged.dat");
  for (std::size_t at = 0; at < 268; ++at) {
    for (char value : {'\xff', '\x7f'}) {
      std::string damaged = bytes;
      damaged[at] = value;
      {
        std::ofstream out(path, std::ios::binary | std::ios::trunc);
        out.write(damaged.data(), static_cast<std::streamsize>(damaged.size()));
      }
      try {
        auto source = OpenSnapshot(path, {});
        ReadAll(*source);
      } catch (const Error& error) {
        ASSERT_EQ(error.kind(), ErrorKind::kBadInput) << "byte " << at << ": " << error.what();
      }
    }
  }
}

TEST_F(SharedDataTest, TruncatedHdf5FilesFailCleanly) {
  SweepTruncations(DataFile("gadget4_hdf5_galaxy_collision_timeseries/snapshot_003.hdf5"), {}, 84731);
}

}  // namespace
}  // namespace octocosm
