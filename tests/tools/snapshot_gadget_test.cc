// GADGET reader tests on files written here: round trips of every variant the
// reader supports (format 1/2, both byte orders, 4/8-byte reals and IDs, mass
// table vs MASS block, multi-file) and the malformed inputs it must reject.
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>

#include <gtest/gtest.h>

#include "storage/error.h"
#include "tests/tools/snapshot_test_util.h"
#include "tools/snapshot/snapshot_source.h"

namespace octocosm {
namespace {

struct GadgetSpec {
  int format = 1;
  bool big_endian = false;
  int real_bytes = 4;  // POS, VEL, MASS
  int id_bytes = 4;
  std::array<std::int32_t, 6> npart{};
  std::array<double, 6> mass_table{};
  std::optional<std::array<std::uint32_t, 6>> total;  // default: npart
  std::array<std::uint32_t, 6> total_high{};
  std::int32_t num_files = 1;
  double time = 0.5, redshift = 1.0, box = 100;
  bool write_velocity = true, write_ids = true, write_mass = true;
  // Per-particle data in file order (type 0 first).
  std::vector<double> position, velocity, mass_block;
  std::vector<std::uint64_t> ids;
};

class Encoder {
 public:
  explicit Encoder(bool big_endian) : big_endian_(big_endian) {}
  template <typename T>
  void Put(T value) {
    std::uint8_t bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    if (big_endian_) std::reverse(bytes, bytes + sizeof(T));
    out_.append(reinterpret_cast<char*>(bytes), sizeof(T));
  }
  void Raw(const std::string& bytes) { out_ += bytes; }
  std::string& bytes() { return out_; }

 private:
  bool big_endian_;
  std::string out_;
};

std::string EncodeGadget(const GadgetSpec& spec) {
  Encoder file(spec.big_endian);
  auto record = [&](const char* name, const std::string& payload) {
    if (spec.format == 2) {
      file.Put<std::int32_t>(8);
      std::string tag = std::string(name) + "    ";
      file.Raw(tag.substr(0, 4));
      file.Put<std::int32_t>(static_cast<std::int32_t>(payload.size() + 8));
      file.Put<std::int32_t>(8);
    }
    file.Put<std::int32_t>(static_cast<std::int32_t>(payload.size()));
    file.Raw(payload);
    file.Put<std::int32_t>(static_cast<std::int32_t>(payload.size()));
  };
  Encoder header(spec.big_endian);
  for (auto n : spec.npart) header.Put<std::int32_t>(n);
  for (auto m : spec.mass_table) header.Put<double>(m);
  header.Put<double>(spec.time);
  header.Put<double>(spec.redshift);
  header.Put<std::int32_t>(0);
  header.Put<std::int32_t>(0);
  for (int t = 0; t < 6; ++t) header.Put<std::uint32_t>(spec.total ? (*spec.total)[t] : static_cast<std::uint32_t>(spec.npart[t]));
  header.Put<std::int32_t>(0);
  header.Put<std::int32_t>(spec.num_files);
  header.Put<double>(spec.box);
  header.Put<double>(0.3);
  header.Put<double>(0.7);
  header.Put<double>(0.7);
  header.Put<std::int32_t>(0);
  header.Put<std::int32_t>(0);
  for (auto h : spec.total_high) header.Put<std::uint32_t>(h);
  header.bytes().resize(256, '\0');
  record("HEAD", header.bytes());

  auto reals = [&](const std::vector<double>& values) {
    Encoder e(spec.big_endian);
    for (double v : values) {
      if (spec.real_bytes == 4) {
        e.Put<float>(static_cast<float>(v));
      } else {
        e.Put<double>(v);
      }
    }
    return e.bytes();
  };
  record("POS", reals(spec.position));
  if (spec.write_velocity) record("VEL", reals(spec.velocity));
  if (spec.write_ids) {
    Encoder e(spec.big_endian);
    for (auto id : spec.ids) {
      if (spec.id_bytes == 4) {
        e.Put<std::uint32_t>(static_cast<std::uint32_t>(id));
      } else {
        e.Put<std::uint64_t>(id);
      }
    }
    record("ID", e.bytes());
  }
  if (spec.write_mass && !spec.mass_block.empty()) record("MASS", reals(spec.mass_block));
  record("U", std::string(16, '\0'));  // a block the reader must skip
  return file.bytes();
}

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

void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
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
  WriteFile(dir.File("snap"), EncodeGadget(spec));
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

TEST(GadgetReader, MultiFileWithZeroNumFilesFindsConsecutiveFiles) {
  ScratchDir dir;
  GadgetSpec a = SmallSpec();
  GadgetSpec b = SmallSpec();
  for (auto& id : b.ids) id += 1000;
  a.total = b.total = std::array<std::uint32_t, 6>{6, 8, 0, 0, 0, 0};
  a.num_files = b.num_files = 0;
  a.format = b.format = 2;
  WriteFile(dir.File("out.0"), EncodeGadget(a));
  WriteFile(dir.File("out.1"), EncodeGadget(b));
  auto source = OpenSnapshot(dir.File("out"), {});
  EXPECT_EQ(source->header().files.size(), 2u);
  EXPECT_EQ(source->header().total_count, 14u);
  ParticleChunk all = ReadAll(*source);
  EXPECT_EQ(all.id.front(), 100u);
  EXPECT_EQ(all.id.back(), 1106u);
}

TEST(GadgetReader, DeclaredFileMissingIsNotFound) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.num_files = 3;
  WriteFile(dir.File("snap.0"), EncodeGadget(spec));
  WriteFile(dir.File("snap.1"), EncodeGadget(spec));
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
  WriteFile(dir.File("snap"), EncodeGadget(spec));
  ExpectBadInput(dir.File("snap"), "counts do not add up: the header total for type 1 is 5");
}

TEST(GadgetReader, JunkHighWordIsIgnoredWhenTheLowWordMatches) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.total_high = {0, 0, 0, 0, 0, 77};
  WriteFile(dir.File("snap"), EncodeGadget(spec));
  auto source = OpenSnapshot(dir.File("snap"), {});
  EXPECT_EQ(source->header().extra["ignored_total_high_words"]["5"], 77);
  EXPECT_EQ(source->header().total_count, 7u);
}

TEST(GadgetReader, BlockSizeDisagreeingWithNpart) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.npart = {3, 5, 0, 0, 0, 0};  // one more particle than the blocks hold
  spec.total = std::array<std::uint32_t, 6>{3, 5, 0, 0, 0, 0};
  WriteFile(dir.File("snap"), EncodeGadget(spec));
  ExpectBadInput(dir.File("snap"), "block POS holds 84 bytes; expected 3 x 8 particles");
}

TEST(GadgetReader, MissingMassBlock) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  spec.format = 2;
  spec.write_mass = false;
  WriteFile(dir.File("snap"), EncodeGadget(spec));
  ExpectBadInput(dir.File("snap"), "missing block MASS");
}

TEST(GadgetReader, DisagreeingRecordMarkers) {
  ScratchDir dir;
  GadgetSpec spec = SmallSpec();
  std::string bytes = EncodeGadget(spec);
  // POS: begin marker at 264, 84 payload bytes, end marker at 352.
  std::string flipped = bytes;
  flipped[352] = 85;
  WriteFile(dir.File("end_marker"), flipped);
  ExpectBadInput(dir.File("end_marker"), "record markers disagree in block POS (record 1) at offset 264");

  flipped = bytes;
  flipped[260] = 1;  // the header's end marker
  WriteFile(dir.File("header_marker"), flipped);
  ExpectBadInput(dir.File("header_marker"), "record markers disagree in block HEAD");

  spec.format = 2;
  bytes = EncodeGadget(spec);
  flipped = bytes;
  flipped[288] = 9;  // the "next block size" of POS's name record
  WriteFile(dir.File("name_record"), flipped);
  ExpectBadInput(dir.File("name_record"), "the name record of block POS");

  flipped = bytes;
  flipped[280] = 7;  // POS's name record begin marker
  WriteFile(dir.File("name_marker"), flipped);
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
      WriteFile(dir.File(name), bytes.substr(0, n));
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
    WriteFile(dir.File("snap"), EncodeGadget(spec));
    ExpectBadInput(dir.File("snap"), "particle type 1 particle 1 (ID 104) has a non-finite coordinate");
  }
}

TEST(GadgetReader, NotAGadgetFile) {
  ScratchDir dir;
  WriteFile(dir.File("junk.dat"), std::string(300, 'x'));
  ExpectBadInput(dir.File("junk.dat"), "unrecognised snapshot format");
  WriteFile(dir.File("empty"), "");
  ExpectBadInput(dir.File("empty"), "empty input");
  ReadOptions forced;
  forced.format = "gadget";
  ExpectBadInput(dir.File("junk.dat"), "not a GADGET file", forced);
}

TEST(GadgetReader, HeaderWithoutParticlesIsEmptyInput) {
  ScratchDir dir;
  GadgetSpec spec;
  WriteFile(dir.File("snap"), EncodeGadget(spec));
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

}  // namespace
}  // namespace octocosm
