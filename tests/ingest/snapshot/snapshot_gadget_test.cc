// GADGET reader tests on files written here: round trips of every variant the
// reader supports (format 1/2, both byte orders, 4/8-byte reals and IDs, mass
// table vs MASS block, multi-file) and the malformed inputs it must reject.
#include <sys/stat.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <gtest/gtest.h>

#include "base/error.h"
#include "ingest/snapshot/snapshot_source.h"
#include "tests/ingest/snapshot/gadget_test_file.h"
#include "tests/ingest/snapshot/snapshot_test_util.h"

namespace octocosm {
namespace {

// A small two-type snapshot: 3 gas particles with MASS-block masses and 4 dark
// matter particles with a table mass.
GadgetSpec SmallSpec() {
  GadgetSpec spec;
  spec.npart = {3, 4, 0, 0, 0, 0};
  spec.mass_table = {0, 2.5, 0, 0, 0, 0};
  for (int i = 0; i < 7; ++i) {
    for (int k = 0; k < 3; ++k) {
      spec.position.push_back(10.0 * i + k + 0.25);
      spec.velocity.push_back(-1.0 * i - k);
    }
    spec.ids.push_back(100 + static_cast<std::uint64_t>(i));
  }
  spec.mass_block = {0.5, 0.75, 1.25};
  return spec;
}

void ExpectMatchesSpec(const ParticleChunk& all, const GadgetSpec& spec) {
  ASSERT_EQ(all.size(), spec.ids.size());
  EXPECT_EQ(all.position, spec.position);
  std::vector<float> velocity(spec.velocity.begin(), spec.velocity.end());
  EXPECT_EQ(all.velocity, velocity);
  EXPECT_EQ(all.id, spec.ids);
  std::size_t mass_index = 0, p = 0;
  for (int t = 0; t < 6; ++t) {
    for (int i = 0; i < spec.npart[t]; ++i, ++p) {
      EXPECT_EQ(all.type[p], t);
      double expected = spec.mass_table[t] != 0 ? spec.mass_table[t] : spec.mass_block[mass_index++];
      EXPECT_EQ(all.mass[p], expected) << p;
    }
  }
}

struct Variant {
  int format;
  bool big_endian;
  int real_bytes;
  int id_bytes;
};

class GadgetRoundTrip : public ::testing::TestWithParam<Variant> {};

TEST_P(GadgetRoundTrip, ReadsBackWhatWasWritten) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.format = GetParam().format;
  spec.big_endian = GetParam().big_endian;
  spec.real_bytes = GetParam().real_bytes;
  spec.id_bytes = GetParam().id_bytes;
  if (spec.id_bytes == 8) spec.ids[6] = (std::uint64_t{1} << 40) + 7;
  WriteBytes(dir.File("snap"), EncodeGadget(spec));
  for (std::size_t chunk : {std::size_t{1}, std::size_t{2}, std::size_t{1000}}) {
    ReadOptions options;
    options.chunk_particles = chunk;
    auto source = OpenSnapshot(dir.File("snap"), options);
    const SnapshotHeader& h = source->header();
    EXPECT_EQ(h.format, spec.format == 2 ? "gadget2" : "gadget1");
    EXPECT_EQ(h.count_per_type, (std::vector<std::uint64_t>{3, 4, 0, 0, 0, 0}));
    EXPECT_EQ(h.time, 0.5);
    EXPECT_EQ(h.redshift, 1.0);
    EXPECT_EQ(h.box_size, 100.0);
    EXPECT_EQ(h.extra["byte_order"], spec.big_endian ? "big-endian" : "little-endian");
    ExpectMatchesSpec(ReadAll(*source), spec);
  }
}

INSTANTIATE_TEST_SUITE_P(Variants, GadgetRoundTrip,
                         ::testing::Values(Variant{1, false, 4, 4}, Variant{1, true, 4, 4}, Variant{2, false, 8, 8},
                                           Variant{2, true, 8, 4}, Variant{1, false, 8, 8}, Variant{2, true, 4, 8}));

// The bytes MappableSegments points at, decoded as a mapping reader would
// (float positions and velocities, 4- or 8-byte IDs, this machine's order).
ParticleChunk ReadMappable(const ParticleSource& source) {
  ParticleChunk all;
  for (const MappableSegment& segment : source.MappableSegments()) {
    std::ifstream in(source.header().files.at(segment.file), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    for (std::uint64_t i = 0; i < segment.count; ++i) {
      for (int a = 0; a < 3; ++a) {
        float x, v;
        std::memcpy(&x, bytes.data() + segment.position_offset + 12 * i + 4 * a, 4);
        std::memcpy(&v, bytes.data() + segment.velocity_offset + 12 * i + 4 * a, 4);
        all.position.push_back(x);
        all.velocity.push_back(v);
      }
      std::uint64_t id = 0;  // little-endian: the low bytes first
      std::memcpy(&id, bytes.data() + segment.id_offset + segment.id_bytes * i, segment.id_bytes);
      all.id.push_back(id);
      all.mass.push_back(segment.mass);
      all.type.push_back(static_cast<std::uint8_t>(segment.type));
    }
  }
  return all;
}

TEST(GadgetReader, MappableSegmentsLieWhereNextReads) {
  static_assert(std::endian::native == std::endian::little, "the files below are written little-endian");
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.npart = {3, 4, 0, 2, 0, 0};  // three types, all with table masses
  spec.mass_table = {0.5, 2.5, 0, 4, 0, 0};
  spec.mass_block.clear();
  for (int i = 7; i < 9; ++i) {
    for (int k = 0; k < 3; ++k) {
      spec.position.push_back(10.0 * i + k + 0.25);
      spec.velocity.push_back(-1.0 * i - k);
    }
    spec.ids.push_back(100 + static_cast<std::uint64_t>(i));
  }
  for (const int format : {1, 2}) {
    for (const int id_bytes : {4, 8}) {
      SCOPED_TRACE("format " + std::to_string(format) + ", IDs of " + std::to_string(id_bytes) + " bytes");
      spec.format = format;
      spec.id_bytes = id_bytes;
      spec.ids[8] = id_bytes == 8 ? (std::uint64_t{1} << 40) + 8 : 108;
      WriteBytes(dir.File("snap"), EncodeGadget(spec));
      for (const std::vector<int>& types : {std::vector<int>{}, std::vector<int>{3, 1}}) {
        ReadOptions options;
        options.types = types;
        auto source = OpenSnapshot(dir.File("snap"), options);
        ASSERT_EQ(source->MappableSegments().size(), types.empty() ? 3u : 2u);
        EXPECT_TRUE(SameParticles(ReadMappable(*source), ReadAll(*source)));
      }
    }
  }
}

TEST(GadgetReader, NoMappableSegmentsWhereAColumnIsNotAPlainFloatArray) {
  ScratchDir dir;
  const auto mappable = [&](const GadgetSpec& spec, const ReadOptions& options = {}) {
    WriteBytes(dir.File("snap"), EncodeGadget(spec));
    return OpenSnapshot(dir.File("snap"), options)->MappableSegments().size();
  };
  GadgetSpec spec = SmallSpec();
  EXPECT_EQ(mappable(spec), 0u) << "the gas particles' masses are in the MASS block";
  ReadOptions dark_matter;
  dark_matter.types = {1};
  EXPECT_EQ(mappable(spec, dark_matter), 1u) << "the dark matter's mass is the table's";
  spec.big_endian = true;
  EXPECT_EQ(mappable(spec, dark_matter), 0u) << "another byte order";
  spec.big_endian = false;
  spec.real_bytes = 8;
  EXPECT_EQ(mappable(spec, dark_matter), 0u) << "double positions";
  spec.real_bytes = 4;
  spec.mass_table[1] = -2.5;  // refused at open: no segment is given out
  WriteBytes(dir.File("snap"), EncodeGadget(spec));
  ExpectBadInput(dir.File("snap"), "header field mass[1] (the mass table) is -2.5", dark_matter);
}

// A format 2 file's HSML block holds one smoothing length per gas (type 0)
// particle; the other types get 0, "not given". Either byte order, float or
// double, any chunk size; read_smoothing = false leaves the column out.
TEST(GadgetReader, Format2HsmlBlockGivesTheGasItsSmoothingLengths) {
  ScratchDir dir;
  for (const bool big_endian : {false, true}) {
    for (const int real_bytes : {4, 8}) {
      SCOPED_TRACE(std::string(big_endian ? "big" : "little") + "-endian, " + std::to_string(real_bytes) + "-byte reals");
      GadgetSpec spec = SmallSpec();
      spec.format = 2;
      spec.big_endian = big_endian;
      spec.real_bytes = real_bytes;
      spec.hsml = {0.75, 1.5, 0.0};
      WriteBytes(dir.File("snap"), EncodeGadget(spec));
      for (std::size_t chunk : {std::size_t{1}, std::size_t{2}, std::size_t{1000}}) {
        ReadOptions options;
        options.chunk_particles = chunk;
        auto source = OpenSnapshot(dir.File("snap"), options);
        EXPECT_TRUE(source->header().has_smoothing);
        EXPECT_EQ(source->header().extra["smoothing_lengths"], "block HSML (gas)");
        const ParticleChunk all = ReadAll(*source);
        EXPECT_EQ(all.smoothing, (std::vector<float>{0.75f, 1.5f, 0, 0, 0, 0, 0}));
        ExpectMatchesSpec(all, spec);
      }
      ReadOptions without;
      without.read_smoothing = false;
      auto source = OpenSnapshot(dir.File("snap"), without);
      EXPECT_FALSE(source->header().has_smoothing);
      EXPECT_TRUE(ReadAll(*source).smoothing.empty());
    }
  }
}

// Format 1 has no block names: which unnamed record would hold smoothing
// lengths depends on how the simulation code was built, so none is read.
TEST(GadgetReader, Format1FilesGiveNoSmoothingLengths) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.format = 1;
  spec.hsml = {0.75, 1.5, 2.0};
  WriteBytes(dir.File("snap"), EncodeGadget(spec));
  auto source = OpenSnapshot(dir.File("snap"), {});
  EXPECT_FALSE(source->header().has_smoothing);
  EXPECT_FALSE(source->header().extra.contains("smoothing_lengths"));
  const ParticleChunk all = ReadAll(*source);
  EXPECT_TRUE(all.smoothing.empty());
  ExpectMatchesSpec(all, spec);
}

// Without gas among the selected types there is nothing to give; a file
// without gas needs no HSML block; a file with gas but without one (or with
// one of another length) leaves the whole snapshot without the column,
// recorded in extra, as a missing VEL block does velocities.
TEST(GadgetReader, SmoothingLengthsForEveryFileWithGasOrForNone) {
  ScratchDir dir;
  GadgetSpec gas = SmallSpec();
  gas.format = 2;
  gas.hsml = {0.75, 1.5, 2.0};
  ReadOptions dark_matter;
  dark_matter.types = {1};
  WriteBytes(dir.File("one"), EncodeGadget(gas));
  EXPECT_FALSE(OpenSnapshot(dir.File("one"), dark_matter)->header().has_smoothing);

  GadgetSpec no_gas = SmallSpec();
  no_gas.format = 2;
  no_gas.npart = {0, 4, 0, 0, 0, 0};
  no_gas.mass_block.clear();
  no_gas.position.erase(no_gas.position.begin(), no_gas.position.begin() + 9);
  no_gas.velocity.erase(no_gas.velocity.begin(), no_gas.velocity.begin() + 9);
  no_gas.ids = {1100, 1101, 1102, 1103};
  GadgetSpec first = gas;
  first.num_files = no_gas.num_files = 2;
  first.total = no_gas.total = std::array<std::uint32_t, 6>{3, 8, 0, 0, 0, 0};
  WriteBytes(dir.File("two.0"), EncodeGadget(first));
  WriteBytes(dir.File("two.1"), EncodeGadget(no_gas));
  auto two = OpenSnapshot(dir.File("two"), {});
  EXPECT_TRUE(two->header().has_smoothing);
  EXPECT_EQ(ReadAll(*two).smoothing, (std::vector<float>{0.75f, 1.5f, 2.0f, 0, 0, 0, 0, 0, 0, 0, 0}));

  GadgetSpec second = gas;
  second.hsml.clear();
  second.num_files = 2;
  second.total = first.total = std::array<std::uint32_t, 6>{6, 8, 0, 0, 0, 0};
  for (auto& id : second.ids) id += 1000;
  WriteBytes(dir.File("three.0"), EncodeGadget(first));
  WriteBytes(dir.File("three.1"), EncodeGadget(second));
  auto three = OpenSnapshot(dir.File("three"), {});
  EXPECT_FALSE(three->header().has_smoothing);
  EXPECT_TRUE(three->header().extra.contains("smoothing_lengths_not_read"));
  EXPECT_TRUE(ReadAll(*three).smoothing.empty());

  GadgetSpec longer = gas;
  longer.hsml = {0.75, 1.5, 2.0, 2.5};  // one for a type 1 particle as well
  WriteBytes(dir.File("four"), EncodeGadget(longer));
  auto four = OpenSnapshot(dir.File("four"), {});
  EXPECT_FALSE(four->header().has_smoothing);
  EXPECT_TRUE(four->header().extra.contains("smoothing_lengths_not_read"));
  ExpectMatchesSpec(ReadAll(*four), longer);
}

TEST(GadgetReader, NegativeOrNonFiniteSmoothingLengthNamesTheBlock) {
  ScratchDir dir;
  for (const double bad : {-0.5, double{NAN}, double{INFINITY}}) {
    GadgetSpec spec = SmallSpec();
    spec.format = 2;
    spec.hsml = {0.75, bad, 2.0};
    WriteBytes(dir.File("snap"), EncodeGadget(spec));
    ExpectBadInput(dir.File("snap"), "particle type 0 particle 1 (ID 101) has smoothing length");
    ExpectBadInput(dir.File("snap"), "in block HSML; smoothing lengths must be finite and >= 0");
    ReadOptions without;
    without.read_smoothing = false;
    auto source = OpenSnapshot(dir.File("snap"), without);
    EXPECT_EQ(ReadAll(*source).size(), 7u) << "not read, not checked";
  }
}

// A segment has no place for smoothing lengths, so a source that gives them
// gives no segments to map: a mapping reader would drop them.
TEST(GadgetReader, NoMappableSegmentsWhereTheChunksCarrySmoothingLengths) {
  static_assert(std::endian::native == std::endian::little, "the file below is written little-endian");
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.format = 2;
  spec.mass_table = {0.5, 2.5, 0, 0, 0, 0};  // table masses for both types: mappable but for the HSML block
  spec.mass_block.clear();
  spec.hsml = {0.75, 1.5, 2.0};
  WriteBytes(dir.File("snap"), EncodeGadget(spec));
  EXPECT_TRUE(OpenSnapshot(dir.File("snap"), {})->MappableSegments().empty());
  ReadOptions without;
  without.read_smoothing = false;
  EXPECT_EQ(OpenSnapshot(dir.File("snap"), without)->MappableSegments().size(), 2u);
  ReadOptions dark_matter;
  dark_matter.types = {1};
  EXPECT_EQ(OpenSnapshot(dir.File("snap"), dark_matter)->MappableSegments().size(), 1u) << "no gas, no smoothing";
}

// out.0 and out.1: two small files of 6 gas and 8 dark-matter particles in all.
void WriteTwoFiles(const ScratchDir& dir, std::int32_t num_files, int format) {
  GadgetSpec a = SmallSpec();
  GadgetSpec b = SmallSpec();
  for (auto& id : b.ids) id += 1000;
  a.total = b.total = std::array<std::uint32_t, 6>{6, 8, 0, 0, 0, 0};
  a.num_files = b.num_files = num_files;
  a.format = b.format = format;
  WriteBytes(dir.File("out.0"), EncodeGadget(a));
  WriteBytes(dir.File("out.1"), EncodeGadget(b));
}

TEST(GadgetReader, MultiFileWithZeroNumFilesFindsConsecutiveFiles) {
  ScratchDir dir;
  WriteTwoFiles(dir, 0, 2);
  auto source = OpenSnapshot(dir.File("out"), {});
  EXPECT_EQ(source->header().files.size(), 2u);
  EXPECT_EQ(source->header().total_count, 14u);
  ParticleChunk all = ReadAll(*source);
  EXPECT_EQ(all.id.front(), 100u);
  EXPECT_EQ(all.id.back(), 1106u);
}

TEST(GadgetReader, SkipPassesOverABatchAcrossTypesAndFiles) {
  ScratchDir dir;
  WriteTwoFiles(dir, 2, SmallSpec().format);
  ReadOptions options;
  options.chunk_particles = 3;
  ExpectSkipPassesOverNextsBatches([&] { return OpenSnapshot(dir.File("out"), options); });
}

TEST(GadgetReader, DeclaredFileMissingIsNotFound) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.num_files = 3;
  WriteBytes(dir.File("snap.0"), EncodeGadget(spec));
  WriteBytes(dir.File("snap.1"), EncodeGadget(spec));
  try {
    OpenSnapshot(dir.File("snap.0"), {});
    ADD_FAILURE() << "missing snap.2 not noticed";
  } catch (const Error& error) {
    EXPECT_EQ(error.kind(), ErrorKind::kNotFound);
    EXPECT_NE(std::string(error.what()).find("snap.2"), std::string::npos) << error.what();
  }
}

TEST(GadgetReader, CountsThatDoNotAddUp) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.total = std::array<std::uint32_t, 6>{3, 5, 0, 0, 0, 0};
  WriteBytes(dir.File("snap"), EncodeGadget(spec));
  ExpectBadInput(dir.File("snap"), "counts do not add up: the header total for type 1 is 5");
}

TEST(GadgetReader, JunkHighWordIsIgnoredWhenTheLowWordMatches) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.total_high = {0, 0, 0, 0, 0, 77};
  WriteBytes(dir.File("snap"), EncodeGadget(spec));
  auto source = OpenSnapshot(dir.File("snap"), {});
  EXPECT_EQ(source->header().extra["ignored_total_high_words"]["5"], 77);
  EXPECT_EQ(source->header().total_count, 7u);
}

TEST(GadgetReader, BlockSizeDisagreeingWithNpart) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.npart = {3, 5, 0, 0, 0, 0};  // one more particle than the blocks hold
  spec.total = std::array<std::uint32_t, 6>{3, 5, 0, 0, 0, 0};
  WriteBytes(dir.File("snap"), EncodeGadget(spec));
  ExpectBadInput(dir.File("snap"), "block POS holds 84 bytes; expected 3 x 8 particles");
}

TEST(GadgetReader, MissingMassBlock) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.format = 2;
  spec.write_mass = false;
  WriteBytes(dir.File("snap"), EncodeGadget(spec));
  ExpectBadInput(dir.File("snap"), "missing block MASS");
}

TEST(GadgetReader, DisagreeingRecordMarkers) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  std::string bytes = EncodeGadget(spec);
  // POS: begin marker at 264, 84 payload bytes, end marker at 352.
  std::string flipped = bytes;
  flipped[352] = 85;
  WriteBytes(dir.File("end_marker"), flipped);
  ExpectBadInput(dir.File("end_marker"), "record markers disagree in block POS (record 1) at offset 264");

  flipped = bytes;
  flipped[260] = 1;  // the header's end marker
  WriteBytes(dir.File("header_marker"), flipped);
  ExpectBadInput(dir.File("header_marker"), "record markers disagree in block HEAD");

  spec.format = 2;
  bytes = EncodeGadget(spec);
  flipped = bytes;
  flipped[288] = 9;  // the "next block size" of POS's name record
  WriteBytes(dir.File("name_record"), flipped);
  ExpectBadInput(dir.File("name_record"), "the name record of block POS");

  flipped = bytes;
  flipped[280] = 7;  // POS's name record begin marker
  WriteBytes(dir.File("name_marker"), flipped);
  ExpectBadInput(dir.File("name_marker"), "block-name record at offset 280 has markers 7 and 8");
}

TEST(GadgetReader, EveryTruncationInsideARecordIsReported) {
  ScratchDir dir;
  for (int format : {1, 2}) {
    GadgetSpec spec = SmallSpec();
    spec.format = format;
    spec.big_endian = format == 2;
    std::string bytes = EncodeGadget(spec);
    // Record boundaries: a file cut there is a shorter but well-formed file.
    std::vector<std::size_t> boundaries;
    std::size_t offset = 0;
    while (offset < bytes.size()) {
      if (format == 2) offset += 16;
      std::uint32_t length;
      std::memcpy(&length, bytes.data() + offset, 4);
      if (spec.big_endian) length = __builtin_bswap32(length);
      offset += 8 + length;
      boundaries.push_back(offset);
    }
    for (std::size_t n = 0; n < bytes.size(); ++n) {
      if (std::find(boundaries.begin(), boundaries.end(), n) != boundaries.end()) continue;
      std::string name = "cut" + std::to_string(format) + "_" + std::to_string(n);
      WriteBytes(dir.File(name), bytes.substr(0, n));
      SCOPED_TRACE(name);
      std::string problem = n == 0 ? "empty input" : n < 4 ? "unrecognised snapshot format" : "truncated";
      ExpectBadInput(dir.File(name), problem);
    }
  }
}

TEST(GadgetReader, NonFiniteCoordinateNamesTheParticle) {
  ScratchDir dir;
  for (double bad : {NAN, INFINITY}) {
    GadgetSpec spec = SmallSpec();
    spec.position[3 * 4 + 1] = bad;  // type 1, second particle, ID 104
    WriteBytes(dir.File("snap"), EncodeGadget(spec));
    ExpectBadInput(dir.File("snap"), "particle type 1 particle 1 (ID 104) has a non-finite coordinate");
  }
}

TEST(GadgetReader, PositionsOnlyLeavesVelocitiesAndIdsUnreadUntilAskedForAgain) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.velocity[3 * 5 + 2] = NAN;  // read, this velocity fails the snapshot
  WriteBytes(dir.File("snap"), EncodeGadget(spec));
  auto source = OpenSnapshot(dir.File("snap"), {});
  ASSERT_TRUE(source->header().has_velocity);
  ASSERT_TRUE(source->header().has_id);

  source->SetPositionsOnly(true);
  ParticleChunk positions, chunk;
  // Not ReadAll: its chunks must carry every column the header announces.
  while (source->Next(chunk)) positions.Append(chunk);
  EXPECT_EQ(positions.position, spec.position);
  EXPECT_EQ(positions.type.size(), 7u);
  EXPECT_EQ(positions.mass.size(), 7u);
  EXPECT_TRUE(positions.velocity.empty());
  EXPECT_TRUE(positions.id.empty());

  source->SetPositionsOnly(false);
  source->Rewind();
  try {
    ReadAll(*source);
    FAIL() << "the non-finite velocity was not read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("non-finite velocity"), std::string::npos) << e.what();
  }
}

TEST(GadgetReader, NotAGadgetFile) {
  ScratchDir dir;
  WriteBytes(dir.File("junk.dat"), std::string(300, 'x'));
  ExpectBadInput(dir.File("junk.dat"), "unrecognised snapshot format");
  WriteBytes(dir.File("empty"), "");
  ExpectBadInput(dir.File("empty"), "empty input");
  ReadOptions forced;
  forced.format = "gadget";
  ExpectBadInput(dir.File("junk.dat"), "not a GADGET file", forced);
}

TEST(GadgetReader, HeaderWithoutParticlesIsEmptyInput) {
  ScratchDir dir;
  GadgetSpec spec;
  WriteBytes(dir.File("snap"), EncodeGadget(spec));
  ExpectBadInput(dir.File("snap"), "empty input");
}

TEST(GadgetReader, MissingSnapshotIsNotFound) {
  ScratchDir dir;
  try {
    OpenSnapshot(dir.File("nothing"), {});
    ADD_FAILURE();
  } catch (const Error& error) {
    EXPECT_EQ(error.kind(), ErrorKind::kNotFound);
    EXPECT_NE(std::string(error.what()).find("nothing.0"), std::string::npos) << error.what();
  }
}

// ---- Numbers from an untrusted header, and particles outside its box ----

TEST(GadgetReader, HeaderNumbersMustBeFinite) {
  ScratchDir dir;
  const double nan = std::nan(""), inf = HUGE_VAL;
  struct Case {
    const char* name;
    void (*spoil)(GadgetSpec&, double);
    double value;
    const char* field;
  };
  const Case cases[] = {
      {"box_nan", [](GadgetSpec& s, double v) { s.box = v; }, nan, "BoxSize is nan"},
      {"box_inf", [](GadgetSpec& s, double v) { s.box = v; }, inf, "BoxSize is inf"},
      {"box_negative", [](GadgetSpec& s, double v) { s.box = v; }, -100, "BoxSize is -100"},
      {"time_nan", [](GadgetSpec& s, double v) { s.time = v; }, nan, "time is nan"},
      {"redshift_inf", [](GadgetSpec& s, double v) { s.redshift = v; }, inf, "redshift is inf"},
      {"table_nan", [](GadgetSpec& s, double v) { s.mass_table[1] = v; }, nan, "mass[1]"},
      {"table_negative", [](GadgetSpec& s, double v) { s.mass_table[1] = v; }, -2.5, "mass[1]"},
  };
  for (const Case& c : cases) {
    GadgetSpec spec = SmallSpec();
    c.spoil(spec, c.value);
    WriteBytes(dir.File(c.name), EncodeGadget(spec));
    ExpectBadInput(dir.File(c.name), c.field);
  }
  // A junk table entry of a type the file does not hold is not used.
  GadgetSpec spec = SmallSpec();
  spec.mass_table[4] = nan;
  WriteBytes(dir.File("junk"), EncodeGadget(spec));
  EXPECT_EQ(ReadAll(*OpenSnapshot(dir.File("junk"), {})).size(), 7u);
}

TEST(GadgetReader, ParticlesFarOutsideThePeriodicBoxAreAnError) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();  // positions up to 62.25
  spec.box = 50;
  WriteBytes(dir.File("small_box"), EncodeGadget(spec));
  ExpectBadInput(dir.File("small_box"), "outside the periodic box [0, 50)^3 of header field BoxSize");
  ExpectBadInput(dir.File("small_box"), "particle type 1 particle 2 (ID 105) lies at (50.25, 51.25, 52.25)");
  // The user's box replaces it; --ignore-box makes the data non-periodic.
  ReadOptions boxed;
  boxed.box_size_override = 100;
  auto source = OpenSnapshot(dir.File("small_box"), boxed);
  EXPECT_EQ(source->header().box_size, 100);
  EXPECT_EQ(source->header().extra["box_size_in_header"], 50);
  EXPECT_EQ(ReadAll(*source).size(), 7u);
  ReadOptions ignoring;
  ignoring.ignore_box = true;
  source = OpenSnapshot(dir.File("small_box"), ignoring);
  EXPECT_EQ(source->header().box_size, 0);
  EXPECT_EQ(ReadAll(*source).size(), 7u);
  // A user's box is held to the same tolerance.
  ReadOptions too_small;
  too_small.box_size_override = 20;
  ExpectBadInput(dir.File("small_box"), "the box size given (--box-size)", too_small);
  // Within 1% of the box outside, particles are taken (ingest wraps them).
  spec.box = 62;  // 62.25 is 0.4% over
  spec.position[0] = -0.5;  // 0.8% under
  WriteBytes(dir.File("near"), EncodeGadget(spec));
  EXPECT_EQ(ReadAll(*OpenSnapshot(dir.File("near"), {})).size(), 7u);
  spec.position[0] = -0.7;  // 1.1% under
  WriteBytes(dir.File("under"), EncodeGadget(spec));
  ExpectBadInput(dir.File("under"), "lies at (-0.7, 1.25, 2.25)");
}

TEST(GadgetReader, BoxOptionsThatContradictEachOther) {
  ScratchDir dir;
  WriteBytes(dir.File("snap"), EncodeGadget(SmallSpec()));
  ReadOptions both;
  both.box_size_override = 10;
  both.ignore_box = true;
  ReadOptions nan_box;
  nan_box.box_size_override = std::nan("");
  for (const ReadOptions& options : {both, nan_box}) {
    try {
      OpenSnapshot(dir.File("snap"), options);
      ADD_FAILURE();
    } catch (const Error& error) {
      EXPECT_EQ(error.kind(), ErrorKind::kInvalidArgument) << error.what();
    }
  }
}

// A directory, a device or a FIFO is said to be what it is, for every format,
// and a FIFO is never opened (the open would wait for a writer).
TEST(SnapshotFiles, NonRegularFilesAreNamedForWhatTheyAre) {
  ScratchDir dir;
  std::filesystem::create_directories(dir.File("a_directory"));
  const std::string fifo = dir.File("a_fifo");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  struct Case {
    std::string path;
    const char* kind;
  };
  const Case cases[] = {{dir.File("a_directory"), "is a directory, not a snapshot file"},
                        {"/dev/null", "is a character device, not a snapshot file"},
                        {"/dev/zero", "is a character device, not a snapshot file"},
                        {fifo, "is a FIFO (named pipe), not a snapshot file"}};
  for (const Case& c : cases) {
    for (const char* format : {"auto", "gadget", "hdf5", "raw", "csv"}) {
      ReadOptions options;
      options.format = format;
      options.raw = RawLayout::Parse("xyz:f32");
      SCOPED_TRACE(c.path + " as " + format);
      ExpectBadInput(c.path, c.kind, options);
    }
  }
  // A member of a multi-file set too.
  GadgetSpec spec = SmallSpec();
  spec.num_files = 2;
  WriteBytes(dir.File("set.0"), EncodeGadget(spec));
  std::filesystem::create_directories(dir.File("set.1"));
  try {
    OpenSnapshot(dir.File("set.0"), {});
    ADD_FAILURE() << "a directory taken as set.1";
  } catch (const Error& error) {
    EXPECT_EQ(error.kind(), ErrorKind::kBadInput) << error.what();
    EXPECT_NE(std::string(error.what()).find(dir.File("set.1") + ": is a directory"), std::string::npos) << error.what();
  }
}

}  // namespace
}  // namespace octocosm
