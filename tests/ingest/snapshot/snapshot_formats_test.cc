// HDF5, raw binary and CSV reader tests on files written here: round trips of
// the supported layouts and the malformed inputs each must reject with a
// BadInput error naming the file and the problem.
#include <hdf5.h>

#include <chrono>
#include <cmath>
#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>

#include <gtest/gtest.h>

#include "base/error.h"
#include "ingest/snapshot/snapshot_source.h"
#include "tests/ingest/snapshot/snapshot_test_util.h"
#include "tests/support/hdf5_writer.h"

namespace octocosm {
namespace {

void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// ---------------------------------------------------------------- HDF5 ----

using testing_support::Hdf5Writer;

// SWIFT's defaults: eta 1.2348 with its cubic spline, gamma 1.825742, and the
// target number of neighbours that follows, (4 pi / 3) (gamma eta)^3.
constexpr float kSwiftEta = 1.2348f;
const float kSwiftNeighbours = static_cast<float>(4 * std::numbers::pi / 3 * std::pow(1.825742 * 1.2348, 3));

// One file of a two-type snapshot: `n0` gas particles with Masses, `n1` dark
// matter particles with a table mass; IDs start at `first_id`.
struct Hdf5Spec {
  std::uint64_t n0 = 3, n1 = 5, first_id = 1;
  std::vector<std::uint64_t> total = {3, 5};
  std::vector<std::uint32_t> total_high;
  int num_files = 1;
  bool write_coordinates = true;
  std::uint64_t coordinate_rows_delta = 0;
  double poison = 0;  // nonzero: stored as x of the second dark matter particle
  // Smoothing lengths of the gas, as dataset PartType0/<smoothing_name> when
  // not empty.
  std::vector<double> smoothing;
  std::string smoothing_name = "SmoothingLength";
  // A SWIFT file (a /Code group), with its kernel's target number of
  // neighbours and eta in /HydroScheme (when hydro_scheme is set).
  bool swift = false;
  bool hydro_scheme = true;
  bool chunked = false;  // datasets in deflated chunks of two rows
};

void WriteHdf5(const std::string& path, const Hdf5Spec& spec) {
  Hdf5Writer w(path, spec.chunked);
  w.Attribute<std::uint32_t>("Header", "NumPart_ThisFile", H5T_NATIVE_UINT32,
                             {static_cast<std::uint32_t>(spec.n0), static_cast<std::uint32_t>(spec.n1)});
  w.Attribute<std::uint64_t>("Header", "NumPart_Total", H5T_NATIVE_UINT64, spec.total);
  if (!spec.total_high.empty()) {
    w.Attribute<std::uint32_t>("Header", "NumPart_Total_HighWord", H5T_NATIVE_UINT32, spec.total_high);
  }
  w.Attribute<double>("Header", "MassTable", H5T_NATIVE_DOUBLE, {0.0, 4.0});
  w.Attribute<std::int32_t>("Header", "NumFilesPerSnapshot", H5T_NATIVE_INT32, {spec.num_files});
  w.Attribute<double>("Header", "Time", H5T_NATIVE_DOUBLE, {0.25});
  w.Attribute<double>("Header", "Redshift", H5T_NATIVE_DOUBLE, {3.0});
  w.Attribute<double>("Header", "BoxSize", H5T_NATIVE_DOUBLE, {250.0});
  w.Attribute<double>("Header", "Omega0", H5T_NATIVE_DOUBLE, {0.31});
  std::uint64_t id = spec.first_id;
  for (int type : {0, 1}) {
    std::uint64_t n = type == 0 ? spec.n0 : spec.n1;
    if (n == 0) continue;
    std::string group = "PartType" + std::to_string(type);
    std::vector<double> coordinates;
    std::vector<float> velocities;
    std::vector<std::uint64_t> ids;
    std::vector<float> masses;
    for (std::uint64_t i = 0; i < n; ++i, ++id) {
      for (int k = 0; k < 3; ++k) {
        coordinates.push_back(static_cast<double>(id) + 0.125 * k);
        velocities.push_back(static_cast<float>(k) - static_cast<float>(id));
      }
      ids.push_back(id);
      masses.push_back(0.5f * static_cast<float>(id));
    }
    if (type == 1 && spec.poison != 0) coordinates[3] = spec.poison;
    coordinates.resize(coordinates.size() + 3 * spec.coordinate_rows_delta, 1.0);
    if (spec.write_coordinates) w.Dataset(group + "/Coordinates", H5T_NATIVE_DOUBLE, coordinates, 3);
    w.Dataset(group + "/Velocities", H5T_NATIVE_FLOAT, velocities, 3);
    w.Dataset(group + "/ParticleIDs", H5T_NATIVE_UINT64, ids, 1);
    if (type == 0) w.Dataset(group + "/Masses", H5T_NATIVE_FLOAT, masses, 1);
    if (type == 0 && !spec.smoothing.empty()) {
      w.Dataset(group + "/" + spec.smoothing_name, H5T_NATIVE_DOUBLE, spec.smoothing, 1);
    }
  }
  if (spec.swift) {
    w.Attribute<std::int32_t>("Code", "Version", H5T_NATIVE_INT32, {1});
    if (spec.hydro_scheme) {
      w.Attribute<float>("HydroScheme", "Kernel target N_ngb", H5T_NATIVE_FLOAT, {kSwiftNeighbours});
      w.Attribute<float>("HydroScheme", "Kernel eta", H5T_NATIVE_FLOAT, {kSwiftEta});
    }
  }
}

TEST(Hdf5Reader, DoubleCoordinatesU64IdsFloatMassesRoundTrip) {
  ScratchDir dir;
  WriteHdf5(dir.File("snap.hdf5"), {});
  ReadOptions options;
  options.chunk_particles = 2;
  auto source = OpenSnapshot(dir.File("snap.hdf5"), options);
  const SnapshotHeader& h = source->header();
  EXPECT_EQ(h.format, "hdf5-gadget");
  EXPECT_EQ(h.count_per_type, (std::vector<std::uint64_t>{3, 5}));
  EXPECT_EQ(h.time, 0.25);
  EXPECT_EQ(h.redshift, 3.0);
  EXPECT_EQ(h.box_size, 250.0);
  EXPECT_EQ(h.omega0, 0.31);
  EXPECT_TRUE(h.cosmological);
  ParticleChunk all = ReadAll(*source);
  ASSERT_EQ(all.size(), 8u);
  for (std::size_t i = 0; i < 8; ++i) {
    EXPECT_EQ(all.id[i], i + 1);
    EXPECT_EQ(all.type[i], i < 3 ? 0 : 1);
    EXPECT_EQ(all.position[3 * i + 2], static_cast<double>(i + 1) + 0.25);
    EXPECT_EQ(all.velocity[3 * i + 1], 1.0f - static_cast<float>(i + 1));
    EXPECT_EQ(all.mass[i], i < 3 ? 0.5 * static_cast<double>(i + 1) : 4.0);
  }
}

// Through the reader process (the default) and in this process alike: a
// pass asking for positions only gets no velocities or IDs, and the next
// read after it gets them again, from any point of a segment (the reader
// reads ahead, and what it read ahead was for the other request).
TEST(Hdf5Reader, PositionsOnlyLeavesVelocitiesAndIdsOutUntilAskedForAgain) {
  ScratchDir dir;
  WriteHdf5(dir.File("snap.hdf5"), {});
  for (const bool isolate : {true, false}) {
    SCOPED_TRACE(isolate ? "reader process" : "this process");
    ReadOptions options;
    options.chunk_particles = 2;
    options.isolate_hdf5 = isolate;
    auto source = OpenSnapshot(dir.File("snap.hdf5"), options);
    const ParticleChunk everything = ReadAll(*source);
    source->Rewind();
    ParticleChunk chunk;
    ASSERT_TRUE(source->Next(chunk));  // particles 0 and 1, with everything
    source->SetPositionsOnly(true);
    std::vector<double> positions(chunk.position);
    std::size_t count = chunk.size();
    while (source->Next(chunk)) {
      EXPECT_TRUE(chunk.velocity.empty());
      EXPECT_TRUE(chunk.id.empty());
      EXPECT_EQ(chunk.mass.size(), chunk.size());
      positions.insert(positions.end(), chunk.position.begin(), chunk.position.end());
      count += chunk.size();
    }
    EXPECT_EQ(count, 8u);
    EXPECT_EQ(positions, everything.position);
    source->SetPositionsOnly(false);
    source->Rewind();
    const ParticleChunk again = ReadAll(*source);
    EXPECT_EQ(again.id, everything.id);
    EXPECT_EQ(again.velocity, everything.velocity);
  }
}

// snap.0.hdf5 and snap.1.hdf5: 5 gas and 9 dark-matter particles in all, IDs 1 to 14.
void WriteTwoFiles(const ScratchDir& dir, const std::vector<std::uint32_t>& total_high) {
  Hdf5Spec first;
  first.num_files = 2;
  first.total = {5, 9};
  first.total_high = total_high;
  Hdf5Spec second = first;
  first.n0 = 2;
  first.n1 = 4;
  second.first_id = 7;
  WriteHdf5(dir.File("snap.0.hdf5"), first);
  WriteHdf5(dir.File("snap.1.hdf5"), second);
}

TEST(Hdf5Reader, MultiFileByBaseNameAndHighWordJunk) {
  ScratchDir dir;
  WriteTwoFiles(dir, {0, 12});  // junk: the low words alone match the file sums
  for (const char* name : {"snap", "snap.1.hdf5"}) {
    auto source = OpenSnapshot(dir.File(name), {});
    EXPECT_EQ(source->header().files,
              (std::vector<std::string>{dir.File("snap.0.hdf5"), dir.File("snap.1.hdf5")}));
    EXPECT_EQ(source->header().count_per_type, (std::vector<std::uint64_t>{5, 9}));
    EXPECT_EQ(source->header().extra["ignored_total_high_words"]["1"], 12);
    ParticleChunk all = ReadAll(*source);
    ASSERT_EQ(all.size(), 14u);
    std::vector<std::uint64_t> expected_ids = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14};
    EXPECT_EQ(all.id, expected_ids);
  }
}

TEST(Hdf5Reader, SkipPassesOverABatchAcrossTypesAndFiles) {
  ScratchDir dir;
  WriteTwoFiles(dir, {});
  ReadOptions options;
  options.chunk_particles = 3;
  ExpectSkipPassesOverNextsBatches([&] { return OpenSnapshot(dir.File("snap"), options); });
}

TEST(Hdf5Reader, SwiftStyleHeader) {
  ScratchDir dir;
  {
    Hdf5Writer w(dir.File("swift.hdf5"));
    w.Attribute<std::uint64_t>("Header", "NumPart_ThisFile", H5T_NATIVE_UINT64, {0, 2});
    w.Attribute<std::uint64_t>("Header", "NumPart_Total", H5T_NATIVE_UINT64, {0, 2});
    w.Attribute<double>("Header", "BoxSize", H5T_NATIVE_DOUBLE, {100, 100, 200});
    w.Attribute<double>("Header", "Time", H5T_NATIVE_DOUBLE, {13.1});
    w.Attribute<std::int32_t>("Header", "NumFilesPerSnapshot", H5T_NATIVE_INT32, {1});
    w.Attribute<double>("Cosmology", "Redshift", H5T_NATIVE_DOUBLE, {1.0});
    w.Attribute<double>("Cosmology", "Scale-factor", H5T_NATIVE_DOUBLE, {0.5});
    w.Attribute<double>("Cosmology", "Omega_m", H5T_NATIVE_DOUBLE, {0.3});
    w.Attribute<double>("Cosmology", "h", H5T_NATIVE_DOUBLE, {0.68});
    w.Attribute<std::int32_t>("Cosmology", "Cosmological run", H5T_NATIVE_INT32, {1});
    w.Attribute<double>("Units", "Unit length in cgs (U_L)", H5T_NATIVE_DOUBLE, {3.08567758e24});
    w.Dataset<float>("PartType1/Coordinates", H5T_NATIVE_FLOAT, {1, 2, 3, 4, 5, 6}, 3);
    w.Dataset<std::uint32_t>("PartType1/ParticleIDs", H5T_NATIVE_UINT32, {10, 11}, 1);
    w.Dataset<double>("PartType1/Masses", H5T_NATIVE_DOUBLE, {7, 8}, 1);
  }
  auto source = OpenSnapshot(dir.File("swift.hdf5"), {});
  const SnapshotHeader& h = source->header();
  EXPECT_EQ(h.format, "hdf5-swift");
  EXPECT_TRUE(h.cosmological);
  EXPECT_EQ(h.time, 0.5);
  EXPECT_EQ(h.redshift, 1.0);
  EXPECT_EQ(h.omega0, 0.3);
  EXPECT_EQ(h.hubble_param, 0.68);
  EXPECT_EQ(h.box_size, 200.0);
  EXPECT_EQ(h.extra["box_size_vector"], (std::vector<double>{100, 100, 200}));
  EXPECT_EQ(h.extra["units"]["Unit length in cgs (U_L)"], 3.08567758e24);
  EXPECT_FALSE(h.has_velocity);  // no Velocities dataset
  ParticleChunk all = ReadAll(*source);
  EXPECT_EQ(all.position, (std::vector<double>{1, 2, 3, 4, 5, 6}));
  EXPECT_EQ(all.id, (std::vector<std::uint64_t>{10, 11}));
  EXPECT_EQ(all.mass, (std::vector<double>{7, 8}));
}

// GADGET-4 and AREPO write the gas's smoothing lengths as
// PartType0/SmoothingLength: read for type 0, 0 ("not given") for the
// others, in chunks that straddle the types.
TEST(Hdf5Reader, SmoothingLengthGivesTheGasItsLengths) {
  ScratchDir dir;
  Hdf5Spec spec;
  spec.smoothing = {0.5, 0.25, 0.0};
  WriteHdf5(dir.File("snap.hdf5"), spec);
  for (std::size_t chunk : {std::size_t{2}, std::size_t{1000}}) {
    ReadOptions options;
    options.chunk_particles = chunk;
    auto source = OpenSnapshot(dir.File("snap.hdf5"), options);
    EXPECT_TRUE(source->header().has_smoothing);
    EXPECT_EQ(source->header().extra["smoothing_lengths"], "dataset /PartType0/SmoothingLength");
    const ParticleChunk all = ReadAll(*source);
    EXPECT_EQ(all.smoothing, (std::vector<float>{0.5f, 0.25f, 0, 0, 0, 0, 0, 0}));
    EXPECT_EQ(all.id, (std::vector<std::uint64_t>{1, 2, 3, 4, 5, 6, 7, 8}));
  }
  ReadOptions without;
  without.read_smoothing = false;
  EXPECT_FALSE(OpenSnapshot(dir.File("snap.hdf5"), without)->header().has_smoothing);
  ReadOptions dark_matter;
  dark_matter.types = {1};
  auto source = OpenSnapshot(dir.File("snap.hdf5"), dark_matter);
  EXPECT_FALSE(source->header().has_smoothing);
  EXPECT_TRUE(ReadAll(*source).smoothing.empty());
}

// SWIFT's h is the kernel's support over gamma; the reader multiplies by
// gamma = (3 N_ngb / (4 pi))^(1/3) / eta from /HydroScheme, and without
// those attributes reads none rather than guess the kernel.
TEST(Hdf5Reader, SwiftSmoothingLengthsBecomeTheKernelsSupportRadius) {
  ScratchDir dir;
  Hdf5Spec spec;
  spec.swift = true;
  spec.smoothing = {0.5, 0.25, 0.0};
  spec.smoothing_name = "SmoothingLengths";
  WriteHdf5(dir.File("swift.hdf5"), spec);
  auto source = OpenSnapshot(dir.File("swift.hdf5"), {});
  EXPECT_EQ(source->header().format, "hdf5-swift");
  ASSERT_TRUE(source->header().has_smoothing);
  const double gamma = std::cbrt(3 * double{kSwiftNeighbours} / (4 * std::numbers::pi)) / double{kSwiftEta};
  EXPECT_NEAR(gamma, 1.825742, 1e-5) << "the cubic spline's";
  const ParticleChunk all = ReadAll(*source);
  ASSERT_EQ(all.smoothing.size(), 8u);
  EXPECT_FLOAT_EQ(all.smoothing[0], static_cast<float>(0.5 * gamma));
  EXPECT_FLOAT_EQ(all.smoothing[1], static_cast<float>(0.25 * gamma));
  for (std::size_t i = 2; i < 8; ++i) EXPECT_EQ(all.smoothing[i], 0.0f) << i;

  spec.hydro_scheme = false;
  WriteHdf5(dir.File("bare.hdf5"), spec);
  auto bare = OpenSnapshot(dir.File("bare.hdf5"), {});
  EXPECT_FALSE(bare->header().has_smoothing);
  EXPECT_TRUE(bare->header().extra.contains("smoothing_lengths_not_read"));
  EXPECT_TRUE(ReadAll(*bare).smoothing.empty());
}

TEST(Hdf5Reader, SmoothingLengthsForEveryFileWithGasOrForNone) {
  ScratchDir dir;
  Hdf5Spec first;
  first.num_files = 2;
  first.total = {6, 10};
  first.smoothing = {0.5, 0.25, 0.125};
  Hdf5Spec second = first;
  second.first_id = 9;
  second.smoothing.clear();
  WriteHdf5(dir.File("snap.0.hdf5"), first);
  WriteHdf5(dir.File("snap.1.hdf5"), second);
  auto source = OpenSnapshot(dir.File("snap"), {});
  EXPECT_FALSE(source->header().has_smoothing);
  EXPECT_TRUE(source->header().extra.contains("smoothing_lengths_not_read"));
  EXPECT_EQ(ReadAll(*source).size(), 16u);
}

TEST(Hdf5Reader, NegativeOrNonFiniteSmoothingLengthNamesTheDataset) {
  ScratchDir dir;
  for (const double bad : {-1.0, double{NAN}, double{INFINITY}}) {
    Hdf5Spec spec;
    spec.smoothing = {0.5, 0.25, bad};
    WriteHdf5(dir.File("snap.hdf5"), spec);
    ExpectBadInput(dir.File("snap.hdf5"), "PartType0 particle 2 (ID 3) has smoothing length");
    ExpectBadInput(dir.File("snap.hdf5"), "in dataset /PartType0/SmoothingLength; smoothing lengths must be finite");
  }
}

TEST(Hdf5Reader, MissingCoordinates) {
  ScratchDir dir;
  Hdf5Spec spec;
  spec.write_coordinates = false;
  WriteHdf5(dir.File("snap.hdf5"), spec);
  ExpectBadInput(dir.File("snap.hdf5"), "missing dataset /PartType0/Coordinates");
}

TEST(Hdf5Reader, DatasetLengthDisagreeingWithHeader) {
  ScratchDir dir;
  Hdf5Spec spec;
  spec.coordinate_rows_delta = 1;
  WriteHdf5(dir.File("snap.hdf5"), spec);
  ExpectBadInput(dir.File("snap.hdf5"), "counts do not add up: dataset /PartType0/Coordinates has 4 x 3 values");
}

TEST(Hdf5Reader, TotalsDisagreeingWithFileCounts) {
  ScratchDir dir;
  Hdf5Spec spec;
  spec.total = {3, 6};
  WriteHdf5(dir.File("snap.hdf5"), spec);
  ExpectBadInput(dir.File("snap.hdf5"), "counts do not add up: the header total for type 1 is 6");
}

TEST(Hdf5Reader, NonFiniteCoordinate) {
  ScratchDir dir;
  Hdf5Spec spec;
  spec.poison = NAN;
  WriteHdf5(dir.File("snap.hdf5"), spec);
  ExpectBadInput(dir.File("snap.hdf5"), "PartType1 particle 1 (ID 5) has a non-finite coordinate");
}

TEST(Hdf5Reader, MissingHeaderAndMissingGroup) {
  ScratchDir dir;
  { Hdf5Writer w(dir.File("empty.hdf5")); }
  ExpectBadInput(dir.File("empty.hdf5"), "unreadable header: missing attribute /Header/NumPart_ThisFile");
  {
    Hdf5Writer w(dir.File("nogroup.hdf5"));
    w.Attribute<std::uint32_t>("Header", "NumPart_ThisFile", H5T_NATIVE_UINT32, {0, 4});
  }
  ExpectBadInput(dir.File("nogroup.hdf5"), "missing group /PartType1");
}

TEST(Hdf5Reader, CorruptFileIsBadInputNotACrash) {
  ScratchDir dir;
  WriteHdf5(dir.File("snap.hdf5"), {});
  std::ifstream in(dir.File("snap.hdf5"), std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (std::size_t n : {std::size_t{8}, std::size_t{100}, bytes.size() / 2, bytes.size() - 1}) {
    WriteFile(dir.File("cut.hdf5"), bytes.substr(0, n));
    ExpectBadInput(dir.File("cut.hdf5"), "");
  }
}

std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// Points the root group's symbol table at the undefined address (all bits
// set) as its local heap, in a file with a version 0 superblock (libhdf5's
// default). libhdf5 1.10.8 then crashes on the first lookup of a name:
// SIGSEGV in H5F__accum_read, from H5Lexists through H5G__stab_lookup and
// H5HL_protect. The superblock's root entry caches the symbol table's B-tree
// and heap addresses (bytes 80 to 95); the same 16 bytes in the root object
// header are its symbol table message, whose heap address is overwritten.
void BreakRootLocalHeap(const std::string& path) {
  std::string bytes = ReadFileBytes(path);
  ASSERT_GT(bytes.size(), 96u);
  ASSERT_EQ(bytes[8], 0) << "expected a version 0 superblock";
  const std::size_t message = bytes.find(bytes.substr(80, 16), 96);
  ASSERT_NE(message, std::string::npos) << "no symbol table message in the root object header";
  std::memset(&bytes[message + 8], 0xff, 8);
  WriteFile(path, bytes);
}

// OpenSnapshot has libhdf5 read an HDF5 file in a process of its own
// (ReadOptions::isolate_hdf5): libhdf5 crashing there is an error naming the
// file, here the one file of a multi-file snapshot that is damaged.
TEST(Hdf5Reader, LibHdf5CrashingOnADamagedFileIsAnErrorNamingTheFile) {
  ScratchDir dir;
  Hdf5Spec spec;
  spec.num_files = 2;
  spec.total = {6, 10};
  WriteHdf5(dir.File("snap.0.hdf5"), spec);
  spec.first_id = 9;
  WriteHdf5(dir.File("snap.1.hdf5"), spec);
  BreakRootLocalHeap(dir.File("snap.1.hdf5"));
  // The damage is one that crashes libhdf5, not one it reports: read in this
  // process, the file kills it.
  ReadOptions in_process;
  in_process.isolate_hdf5 = false;
  EXPECT_DEATH(OpenSnapshot(dir.File("snap.1.hdf5"), in_process), "");
  // "was killed by signal 11 (Segmentation fault)"; under AddressSanitizer,
  // whose handler reports the fault and exits, "exited with status 1".
  ExpectBadInput(dir.File("snap.1.hdf5"), "libhdf5 failed reading this file's metadata: the process reading it ");
  for (const char* name : {"snap", "snap.0.hdf5"}) {
    try {
      OpenSnapshot(dir.File(name), {});
      ADD_FAILURE() << "no error for " << name;
    } catch (const Error& error) {
      EXPECT_EQ(error.kind(), ErrorKind::kBadInput);
      EXPECT_EQ(std::string(error.what()).rfind(dir.File("snap.1.hdf5") + ": libhdf5 failed", 0), 0u) << error.what();
    }
  }
}

// The source built from what the reader process found reads as one that
// walked the files itself, and the reader's Error comes back as it was thrown.
TEST(Hdf5Reader, IsolatedAndInProcessReadsAgree) {
  ScratchDir dir;
  Hdf5Spec spec;
  spec.num_files = 2;
  spec.total = {6, 10};
  spec.swift = true;
  spec.smoothing = {0.5, 1.0, 1.5};
  spec.smoothing_name = "SmoothingLengths";
  WriteHdf5(dir.File("snap.0.hdf5"), spec);
  spec.first_id = 9;
  WriteHdf5(dir.File("snap.1.hdf5"), spec);
  ReadOptions in_process;
  in_process.isolate_hdf5 = false;
  in_process.chunk_particles = 5;
  ReadOptions isolated = in_process;
  isolated.isolate_hdf5 = true;
  auto a = OpenSnapshot(dir.File("snap"), in_process);
  auto b = OpenSnapshot(dir.File("snap"), isolated);
  const SnapshotHeader& ha = a->header();
  const SnapshotHeader& hb = b->header();
  EXPECT_EQ(ha.format, hb.format);
  EXPECT_EQ(ha.files, hb.files);
  EXPECT_EQ(ha.time, hb.time);
  EXPECT_EQ(ha.redshift, hb.redshift);
  EXPECT_EQ(ha.box_size, hb.box_size);
  EXPECT_EQ(ha.count_per_type, hb.count_per_type);
  EXPECT_EQ(ha.total_count, hb.total_count);
  EXPECT_EQ(ha.has_velocity, hb.has_velocity);
  EXPECT_EQ(ha.has_id, hb.has_id);
  EXPECT_EQ(ha.has_smoothing, hb.has_smoothing);
  EXPECT_EQ(ha.cosmological, hb.cosmological);
  EXPECT_EQ(ha.omega0, hb.omega0);
  EXPECT_EQ(ha.extra, hb.extra);
  EXPECT_TRUE(ha.has_smoothing);
  const ParticleChunk pa = ReadAll(*a);
  const ParticleChunk pb = ReadAll(*b);
  EXPECT_EQ(pa.size(), 16u);
  EXPECT_TRUE(SameParticles(pa, pb));
  EXPECT_EQ(pa.smoothing, pb.smoothing);

  Hdf5Spec short_coordinates;
  short_coordinates.coordinate_rows_delta = 1;
  WriteHdf5(dir.File("bad.hdf5"), short_coordinates);
  std::string messages[2];
  for (int i = 0; i < 2; ++i) {
    try {
      OpenSnapshot(dir.File("bad.hdf5"), i == 0 ? in_process : isolated);
    } catch (const Error& error) {
      EXPECT_EQ(error.kind(), ErrorKind::kBadInput);
      messages[i] = error.what();
    }
  }
  EXPECT_FALSE(messages[0].empty());
  EXPECT_EQ(messages[0], messages[1]);
}

// ---- Numbers from an untrusted header, and datasets bounded before they are read ----

// A file of `n` type-1 particles: header attributes as given, then the
// datasets the caller writes.
void WriteHdf5Header(Hdf5Writer& w, std::uint64_t n, double box = 250, double time = 0.25) {
  w.Attribute<std::uint64_t>("Header", "NumPart_ThisFile", H5T_NATIVE_UINT64, {0, n});
  w.Attribute<std::uint64_t>("Header", "NumPart_Total", H5T_NATIVE_UINT64, {0, n});
  w.Attribute<double>("Header", "MassTable", H5T_NATIVE_DOUBLE, {0.0, 4.0});
  w.Attribute<double>("Header", "BoxSize", H5T_NATIVE_DOUBLE, {box});
  w.Attribute<double>("Header", "Time", H5T_NATIVE_DOUBLE, {time});
}

TEST(Hdf5Reader, HeaderNumbersMustBeFinite) {
  ScratchDir dir;
  const double nan = std::nan("");
  struct Case {
    const char* name;
    const char* attribute;
    std::vector<double> value;
    const char* message;
  };
  const Case cases[] = {
      {"box_nan", "BoxSize", {nan}, "BoxSize is nan"},
      {"box_negative", "BoxSize", {-250}, "BoxSize is -250"},
      {"box_vector_nan", "BoxSize", {250, nan, 250}, "BoxSize is nan"},
      {"time_nan", "Time", {nan}, "Time is nan"},
      {"redshift_inf", "Redshift", {HUGE_VAL}, "Redshift is inf"},
      {"omega_nan", "Omega0", {nan}, "Omega0 is nan"},
      {"table_nan", "MassTable", {0, nan}, "MassTable holds nan"},
  };
  for (const Case& c : cases) {
    const std::string path = dir.File(std::string(c.name) + ".hdf5");
    {
      Hdf5Writer w(path);
      w.Attribute<std::uint64_t>("Header", "NumPart_ThisFile", H5T_NATIVE_UINT64, {0, 2});
      for (const char* name : {"BoxSize", "Time", "Redshift", "Omega0", "MassTable"}) {
        if (std::strcmp(name, c.attribute) == 0) {
          w.Attribute<double>("Header", name, H5T_NATIVE_DOUBLE, c.value);
        } else {
          w.Attribute<double>("Header", name, H5T_NATIVE_DOUBLE, std::strcmp(name, "MassTable") == 0
                                                                      ? std::vector<double>{0, 4}
                                                                      : std::vector<double>{0.5});
        }
      }
      w.Dataset<double>("PartType1/Coordinates", H5T_NATIVE_DOUBLE, {0.25, 0.25, 0.25, 0.3, 0.3, 0.3}, 3);
    }
    SCOPED_TRACE(c.name);
    ExpectBadInput(path, c.message);
  }
}

TEST(Hdf5Reader, ParticlesFarOutsideThePeriodicBoxAreAnError) {
  ScratchDir dir;
  {
    Hdf5Writer w(dir.File("snap.hdf5"));
    WriteHdf5Header(w, 2, 1000);
    w.Dataset<double>("PartType1/Coordinates", H5T_NATIVE_DOUBLE, {10, 20, 30, 40000, 50000, 20}, 3);
  }
  ExpectBadInput(dir.File("snap.hdf5"), "PartType1 particle 1 lies at (40000, 50000, 20), more than 1% of the box "
                                        "outside the periodic box [0, 1000)^3 of header field BoxSize");
  ReadOptions ignoring;
  ignoring.ignore_box = true;
  EXPECT_EQ(ReadAll(*OpenSnapshot(dir.File("snap.hdf5"), ignoring)).size(), 2u);
  ReadOptions boxed;
  boxed.box_size_override = 50000;
  EXPECT_EQ(ReadAll(*OpenSnapshot(dir.File("snap.hdf5"), boxed)).size(), 2u);
}

TEST(Hdf5Reader, SignedIdsAreReadAndNegativeOnesRefused) {
  ScratchDir dir;
  for (const bool negative : {false, true}) {
    const std::string path = dir.File(negative ? "negative.hdf5" : "signed.hdf5");
    {
      Hdf5Writer w(path);
      WriteHdf5Header(w, 3);
      w.Dataset<double>("PartType1/Coordinates", H5T_NATIVE_DOUBLE, {1, 1, 1, 2, 2, 2, 3, 3, 3}, 3);
      w.Dataset<std::int64_t>("PartType1/ParticleIDs", H5T_NATIVE_INT64,
                              {5, negative ? -7 : (std::int64_t{1} << 40), 9}, 1);
    }
    if (negative) {
      ExpectBadInput(path, "PartType1 particle 1 has a negative ID (-7) in dataset /PartType1/ParticleIDs");
    } else {
      EXPECT_EQ(ReadAll(*OpenSnapshot(path, {})).id, (std::vector<std::uint64_t>{5, std::uint64_t{1} << 40, 9}));
    }
  }
}

TEST(Hdf5Reader, CountsMustBeWholeNumbersAtLeastZero) {
  ScratchDir dir;
  {
    Hdf5Writer w(dir.File("snap.hdf5"));
    w.Attribute<std::int32_t>("Header", "NumPart_ThisFile", H5T_NATIVE_INT32, {0, -3});
    w.Attribute<double>("Header", "MassTable", H5T_NATIVE_DOUBLE, {0.0, 4.0});
  }
  ExpectBadInput(dir.File("snap.hdf5"), "attribute /Header/NumPart_ThisFile holds -3");
  {
    Hdf5Writer w(dir.File("float.hdf5"));
    w.Attribute<double>("Header", "NumPart_ThisFile", H5T_NATIVE_DOUBLE, {0, 2.5});
  }
  ExpectBadInput(dir.File("float.hdf5"), "a count must be a whole number");
}

// Writes dataset PartType1/Coordinates of `rows` x 3 doubles with the
// creation properties `dcpl`, and the first `written` rows of values.
void WriteCoordinates(const std::string& path, std::uint64_t rows, hid_t dcpl, std::uint64_t written) {
  {
    Hdf5Writer w(path);
    WriteHdf5Header(w, rows);
    w.Attribute<double>("PartType1", "unused", H5T_NATIVE_DOUBLE, {0});  // makes the group
  }
  hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  hsize_t dims[2] = {rows, 3};
  hid_t space = H5Screate_simple(2, dims, nullptr);
  hid_t dataset = H5Dcreate2(file, "PartType1/Coordinates", H5T_NATIVE_DOUBLE, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
  ASSERT_GE(dataset, 0);
  if (written > 0) {
    std::vector<double> values(3 * written, 1.0);
    hsize_t start[2] = {0, 0}, count[2] = {written, 3};
    H5Sselect_hyperslab(space, H5S_SELECT_SET, start, nullptr, count, nullptr);
    hid_t memory = H5Screate_simple(2, count, nullptr);
    EXPECT_GE(H5Dwrite(dataset, H5T_NATIVE_DOUBLE, memory, space, H5P_DEFAULT, values.data()), 0);
    H5Sclose(memory);
  }
  H5Dclose(dataset);
  H5Sclose(space);
  H5Fclose(file);
}

// The files a process has open, by their paths (/proc/self/fd).
std::vector<std::string> OpenFiles() {
  std::vector<std::string> paths;
  for (const auto& entry : std::filesystem::directory_iterator("/proc/self/fd")) {
    std::error_code error;
    const std::filesystem::path target = std::filesystem::read_symlink(entry.path(), error);
    if (!error) paths.push_back(target.string());
  }
  return paths;
}

// Every libhdf5 call on a snapshot happens in its reader process: this
// process does not open the file, not even while it reads the particles.
TEST(Hdf5Reader, OnlyTheReaderProcessOpensTheFile) {
  ScratchDir dir;
  WriteHdf5(dir.File("snap.hdf5"), {});
  const std::string path = std::filesystem::canonical(dir.File("snap.hdf5")).string();
  ReadOptions options;
  options.chunk_particles = 2;
  for (bool isolated : {false, true}) {
    options.isolate_hdf5 = isolated;
    auto source = OpenSnapshot(path, options);
    ParticleChunk chunk;
    ASSERT_TRUE(source->Next(chunk));
    const std::vector<std::string> open = OpenFiles();
    // In this process, libhdf5 holds the file open between reads.
    EXPECT_EQ(std::count(open.begin(), open.end(), path), isolated ? 0 : 1) << "isolated " << isolated;
  }
}

// A damaged chunk between a dataset's first and last, which the open does
// not read, fails when its rows are read: in the reader process, and comes
// back as the error libhdf5 gave there, naming the file and the rows.
TEST(Hdf5Reader, ADamagedChunkInTheMiddleIsAnErrorNamingTheFileAndTheRows) {
  ScratchDir dir;
  const std::string path = dir.File("snap.hdf5");
  Hdf5Spec spec;
  spec.n0 = 0;
  spec.n1 = 40;
  spec.total = {0, 40};
  spec.chunked = true;
  WriteHdf5(path, spec);
  haddr_t address = HADDR_UNDEF;
  hsize_t size = 0;
  {
    const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    const hid_t dataset = H5Dopen2(file, "PartType1/Coordinates", H5P_DEFAULT);
    hsize_t offset[2] = {0, 0};
    unsigned filters = 0;
    const hid_t space = H5Dget_space(dataset);
    // Chunk 10 holds rows 20 and 21.
    EXPECT_GE(H5Dget_chunk_info(dataset, space, 10, offset, &filters, &address, &size), 0);
    EXPECT_EQ(offset[0], 20u);
    H5Sclose(space);
    H5Dclose(dataset);
    H5Fclose(file);
  }
  ASSERT_NE(address, HADDR_UNDEF);
  std::string bytes = ReadFileBytes(path);
  ASSERT_LE(address + size, bytes.size());
  std::memset(&bytes[address], 0xa5, size);
  WriteFile(path, bytes);

  for (bool isolated : {false, true}) {
    ReadOptions options;
    options.chunk_particles = 8;
    options.isolate_hdf5 = isolated;
    auto source = OpenSnapshot(path, options);  // reads rows 0 and 39
    ParticleChunk chunk;
    try {
      while (source->Next(chunk)) {
      }
      ADD_FAILURE() << "no error, isolated " << isolated;
    } catch (const Error& error) {
      EXPECT_EQ(error.kind(), ErrorKind::kBadInput);
      const std::string what = error.what();
      EXPECT_EQ(what.rfind(path + ": cannot read rows 16..24 of dataset /PartType1/Coordinates", 0), 0u) << what;
    }
  }
}

// A small file declaring 2^33 particles is refused at open, before libhdf5
// reads (or makes up) a value: a dataset holds no more bytes than the file,
// nor, compressed, more than 2048 times what it stores.
TEST(Hdf5Reader, DeclaredCountsTheFileCannotHoldAreRefusedAtOnce) {
  ScratchDir dir;
  const std::uint64_t huge = std::uint64_t{1} << 33;
  const auto start = std::chrono::steady_clock::now();
  {
    // Contiguous, never written: no storage at all.
    WriteCoordinates(dir.File("contiguous.hdf5"), huge, H5P_DEFAULT, 0);
    ExpectBadInput(dir.File("contiguous.hdf5"), "stores none of them (never written)");
  }
  hid_t chunked = H5Pcreate(H5P_DATASET_CREATE);
  hsize_t chunk[2] = {1024, 3};
  H5Pset_chunk(chunked, 2, chunk);
  WriteCoordinates(dir.File("chunked.hdf5"), huge, chunked, 0);
  ExpectBadInput(dir.File("chunked.hdf5"), "stores none of them (never written)");
  WriteCoordinates(dir.File("one_chunk.hdf5"), huge, chunked, 1024);
  ExpectBadInput(dir.File("one_chunk.hdf5"), "stores only 24576 bytes");
  // A small chunked dataset partly written: the unwritten rows would be fill values.
  WriteCoordinates(dir.File("partly.hdf5"), 4096, chunked, 1024);
  ExpectBadInput(dir.File("partly.hdf5"), "stores only 24576 bytes");
  // Chunks of more than 256 MiB are not allocated for libhdf5.
  hid_t big_chunks = H5Pcreate(H5P_DATASET_CREATE);
  hsize_t big_chunk[2] = {std::uint64_t{1} << 24, 3};
  H5Pset_chunk(big_chunks, 2, big_chunk);
  WriteCoordinates(dir.File("big_chunks.hdf5"), huge, big_chunks, 0);
  ExpectBadInput(dir.File("big_chunks.hdf5"), "stored in chunks of");
  H5Pclose(big_chunks);
  // Compressed, one chunk written: far beyond what deflate can do.
  H5Pset_shuffle(chunked);
  H5Pset_deflate(chunked, 6);
  WriteCoordinates(dir.File("deflated_chunk.hdf5"), huge, chunked, 1024);
  ExpectBadInput(dir.File("deflated_chunk.hdf5"), "2048:1 compressed");
  // Compressed, fully written data reads back.
  WriteCoordinates(dir.File("deflated.hdf5"), 5000, chunked, 5000);
  EXPECT_EQ(ReadAll(*OpenSnapshot(dir.File("deflated.hdf5"), {})).size(), 5000u);
  H5Pclose(chunked);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 30.0);
}

// A filter not built into libhdf5 (one it would look for among plugins) is
// not used: here LZ4's registered number, set optional so that the writer
// may skip it.
TEST(Hdf5Reader, FiltersOutsideTheBuiltInOnesAreRefused) {
  ScratchDir dir;
  hid_t plugin = H5Pcreate(H5P_DATASET_CREATE);
  hsize_t chunk[2] = {2, 3};
  H5Pset_chunk(plugin, 2, chunk);
  ASSERT_GE(H5Pset_filter(plugin, 32004, H5Z_FLAG_OPTIONAL, 0, nullptr), 0);
  WriteCoordinates(dir.File("plugin.hdf5"), 2, plugin, 2);
  H5Pclose(plugin);
  ExpectBadInput(dir.File("plugin.hdf5"), "uses filter 32004");
}

// Values that would come from outside the file are not read.
TEST(Hdf5Reader, ExternalStorageIsRefused) {
  ScratchDir dir;
  hid_t external = H5Pcreate(H5P_DATASET_CREATE);
  ASSERT_GE(H5Pset_external(external, "/dev/zero", 0, 2 * 3 * sizeof(double)), 0);
  WriteCoordinates(dir.File("external.hdf5"), 2, external, 0);
  H5Pclose(external);
  ExpectBadInput(dir.File("external.hdf5"), "keeps its values in external files");
}

// ----------------------------------------------------------------- raw ----

TEST(RawLayout, ParsesTheGrammar) {
  RawLayout simple = RawLayout::Parse("x,y,z:f32");
  EXPECT_EQ(simple.record_bytes, 12u);
  EXPECT_EQ(simple.columns.size(), 3u);
  EXPECT_EQ(simple.columns[1].scalar, RawColumn::Scalar::kF32);
  EXPECT_FALSE(simple.big_endian);

  RawLayout full = RawLayout::Parse(">xyz:f64, vel:f32x3, mass:f64, skip:u32x2, id:u64");
  EXPECT_TRUE(full.big_endian);
  EXPECT_EQ(full.record_bytes, 24u + 12u + 8u + 8u + 8u);
  EXPECT_TRUE(full.has(RawColumn::Field::kVx));
  EXPECT_EQ(full.columns.back().field, RawColumn::Field::kId);
  EXPECT_EQ(full.columns.back().offset, 52u);

  for (const char* bad : {"", "x,y:f32", "x,y,z", "x,y,z:f99", "x,y,z:f32,vx:f32", "x,x,y,z:f32",
                          "xyz:f32x2", "xyz:f32,id:f64", "xyz:f32,,mass:f32", "xyz:f32,color:u32", "skip:f32x0,xyz:f32"}) {
    SCOPED_TRACE(bad);
    try {
      RawLayout::Parse(bad);
      ADD_FAILURE() << "accepted";
    } catch (const Error& error) {
      EXPECT_EQ(error.kind(), ErrorKind::kInvalidArgument);
      EXPECT_NE(std::string(error.what()).find("raw layout"), std::string::npos);
    }
  }
}

template <typename T>
void Append(std::string& bytes, T value, bool big_endian = false) {
  char raw[sizeof(T)];
  std::memcpy(raw, &value, sizeof(T));
  if (big_endian) std::reverse(raw, raw + sizeof(T));
  bytes.append(raw, sizeof(T));
}

TEST(RawReader, RoundTripWithAllColumnsBigEndian) {
  ScratchDir dir;
  std::string bytes;
  for (int i = 0; i < 5; ++i) {
    for (int k = 0; k < 3; ++k) Append<double>(bytes, i * 3.0 + k, true);
    for (int k = 0; k < 3; ++k) Append<float>(bytes, static_cast<float>(-k), true);
    Append<std::uint32_t>(bytes, 0xdeadbeef, true);  // skipped
    Append<float>(bytes, 0.5f * static_cast<float>(i + 1), true);
    Append<std::uint64_t>(bytes, (std::uint64_t{1} << 50) + static_cast<std::uint64_t>(i), true);
  }
  WriteFile(dir.File("particles.bin"), bytes);
  ReadOptions options;
  options.format = "raw";
  options.raw = RawLayout::Parse(">xyz:f64,vel:f32,skip:u32,mass:f32,id:u64");
  options.chunk_particles = 2;
  auto source = OpenSnapshot(dir.File("particles.bin"), options);
  EXPECT_EQ(source->header().format, "raw");
  EXPECT_EQ(source->header().count_per_type, (std::vector<std::uint64_t>{5}));
  ParticleChunk all = ReadAll(*source);
  ASSERT_EQ(all.size(), 5u);
  for (std::size_t i = 0; i < 5; ++i) {
    EXPECT_EQ(all.position[3 * i + 2], static_cast<double>(i) * 3.0 + 2);
    EXPECT_EQ(all.velocity[3 * i + 1], -1.0f);
    EXPECT_EQ(all.mass[i], 0.5 * static_cast<double>(i + 1));
    EXPECT_EQ(all.id[i], (std::uint64_t{1} << 50) + i);
  }
}

TEST(RawReader, PositionsOnlyGetUnitMass) {
  ScratchDir dir;
  std::string bytes;
  for (int i = 0; i < 4; ++i) {
    for (int k = 0; k < 3; ++k) Append<float>(bytes, static_cast<float>(i + k));
  }
  WriteFile(dir.File("p.bin"), bytes);
  ReadOptions options;
  options.format = "raw";
  options.raw = RawLayout::Parse("x,y,z:f32");
  auto source = OpenSnapshot(dir.File("p.bin"), options);
  EXPECT_FALSE(source->header().has_velocity);
  EXPECT_FALSE(source->header().has_id);
  ParticleChunk all = ReadAll(*source);
  EXPECT_EQ(all.mass, (std::vector<double>{1, 1, 1, 1}));
  EXPECT_EQ(all.position[9], 3.0);
}

TEST(RawReader, MalformedInputs) {
  ScratchDir dir;
  ReadOptions options;
  options.format = "raw";
  options.raw = RawLayout::Parse("xyz:f32");
  WriteFile(dir.File("short.bin"), std::string(12 * 3 + 5, '\0'));
  ExpectBadInput(dir.File("short.bin"), "file size 41 is not a whole number of 12-byte records", options);
  WriteFile(dir.File("empty.bin"), "");
  ExpectBadInput(dir.File("empty.bin"), "empty input", options);
  std::string bytes;
  for (float v : {1.0f, 2.0f, 3.0f, 4.0f, INFINITY, 6.0f}) Append<float>(bytes, v);
  WriteFile(dir.File("inf.bin"), bytes);
  ExpectBadInput(dir.File("inf.bin"), "record 1 has a non-finite coordinate", options);
  // Masses must be finite and > 0, velocities finite: the octree's weights
  // and columns cannot take anything else.
  ReadOptions with_mass = options;
  with_mass.raw = RawLayout::Parse("xyz:f32,vel:f32,mass:f64");
  const auto record = [](float v, double mass) {
    std::string r;
    for (float x : {1.0f, 2.0f, 3.0f, v, 0.0f, 0.0f}) Append<float>(r, x);
    Append<double>(r, mass);
    return r;
  };
  WriteFile(dir.File("nan_mass.bin"), record(0, 1) + record(0, NAN));
  ExpectBadInput(dir.File("nan_mass.bin"), "record 1 has mass nan; masses must be finite and > 0", with_mass);
  WriteFile(dir.File("zero_mass.bin"), record(0, 0));
  ExpectBadInput(dir.File("zero_mass.bin"), "record 0 has mass 0; masses must be finite and > 0", with_mass);
  WriteFile(dir.File("negative_mass.bin"), record(0, -2));
  ExpectBadInput(dir.File("negative_mass.bin"), "record 0 has mass -2", with_mass);
  WriteFile(dir.File("inf_velocity.bin"), record(0, 1) + record(0, 1) + record(-INFINITY, 1));
  ExpectBadInput(dir.File("inf_velocity.bin"), "record 2 has a non-finite velocity (-inf, 0, 0)", with_mass);

  ReadOptions no_layout;
  no_layout.format = "raw";
  try {
    OpenSnapshot(dir.File("inf.bin"), no_layout);
    ADD_FAILURE();
  } catch (const Error& error) {
    EXPECT_EQ(error.kind(), ErrorKind::kInvalidArgument);
  }
}

// ----------------------------------------------------------------- CSV ----

TEST(CsvReader, CommaSeparatedWithOptionalColumns) {
  ScratchDir dir;
  WriteFile(dir.File("p.csv"),
            "# exported by a test\n"
            "id, X, y, z, vx, vy, vz, mass, colour\n"
            "7, 1.5, 2, 3, 0.5, 0.25, -1, 2e-3, red\r\n"
            "\n"
            "8, -1e3, 0, 4.25, 0, 0, 0, 1, blue\n");
  ReadOptions options;
  options.chunk_particles = 1;
  auto source = OpenSnapshot(dir.File("p.csv"), options);
  EXPECT_EQ(source->header().format, "csv");
  EXPECT_EQ(source->header().total_count, 2u);
  EXPECT_TRUE(source->header().has_velocity);
  EXPECT_TRUE(source->header().has_id);
  for (int pass = 0; pass < 2; ++pass) {
    ParticleChunk all = ReadAll(*source);
    EXPECT_EQ(all.position, (std::vector<double>{1.5, 2, 3, -1000, 0, 4.25}));
    EXPECT_EQ(all.velocity, (std::vector<float>{0.5f, 0.25f, -1, 0, 0, 0}));
    EXPECT_EQ(all.mass, (std::vector<double>{2e-3, 1}));
    EXPECT_EQ(all.id, (std::vector<std::uint64_t>{7, 8}));
    source->Rewind();
  }
}

TEST(CsvReader, SkipReadsThroughTheRowsItPassesOver) {
  ScratchDir dir;
  std::string text = "x,y,z\n";
  for (int i = 0; i < 10; ++i) text += std::to_string(i) + ",0.5," + std::to_string(2 * i) + "\n";
  WriteFile(dir.File("p.csv"), text);
  ReadOptions options;
  options.chunk_particles = 2;
  ExpectSkipPassesOverNextsBatches([&] { return OpenSnapshot(dir.File("p.csv"), options); });
}

TEST(CsvReader, WhitespaceSeparatedNeedsExplicitFormatWithoutCsvSuffix) {
  ScratchDir dir;
  WriteFile(dir.File("points.txt"), "x y z\n1 2 3\n\t4   5 6  \n");
  ReadOptions options;
  options.format = "csv";
  auto source = OpenSnapshot(dir.File("points.txt"), options);
  ParticleChunk all = ReadAll(*source);
  EXPECT_EQ(all.position, (std::vector<double>{1, 2, 3, 4, 5, 6}));
  EXPECT_EQ(all.mass, (std::vector<double>{1, 1}));
  EXPECT_FALSE(all.has_id());
}

TEST(CsvReader, MalformedRowsNameTheLine) {
  ScratchDir dir;
  WriteFile(dir.File("bad_number.csv"), "x,y,z\n1,2,3\n4,five,6\n");
  ExpectBadInput(dir.File("bad_number.csv"), "line 3: column y: cannot read \"five\" as a number");
  WriteFile(dir.File("fields.csv"), "x,y,z,mass\n1,2,3,4\n\n1,2,3\n");
  ExpectBadInput(dir.File("fields.csv"), "line 4: 3 fields, but the header row names 4");
  WriteFile(dir.File("nan.csv"), "x,y,z\n1,2,3\n1,nan,3\n");
  ExpectBadInput(dir.File("nan.csv"), "line 3: non-finite coordinate");
  WriteFile(dir.File("mass.csv"), "x,y,z,mass\n1,2,3,1\n1,2,3,inf\n");
  ExpectBadInput(dir.File("mass.csv"), "line 3: mass inf; masses must be finite and > 0");
  WriteFile(dir.File("zero.csv"), "x,y,z,mass\n1,2,3,0\n");
  ExpectBadInput(dir.File("zero.csv"), "line 2: mass 0.000000; masses must be finite and > 0");
  WriteFile(dir.File("velocity.csv"), "x,y,z,vx,vy,vz\n1,2,3,0,nan,0\n");
  ExpectBadInput(dir.File("velocity.csv"), "line 2: non-finite velocity");
  WriteFile(dir.File("noz.csv"), "x,y,mass\n1,2,3\n");
  ExpectBadInput(dir.File("noz.csv"), "line 1: the header row must name columns x, y and z");
  WriteFile(dir.File("id.csv"), "x,y,z,id\n1,2,3,-4\n");
  ExpectBadInput(dir.File("id.csv"), "line 2: column id: cannot read \"-4\" as an unsigned integer");
  WriteFile(dir.File("rows.csv"), "x,y,z\n# nothing\n");
  ExpectBadInput(dir.File("rows.csv"), "empty input");
  WriteFile(dir.File("blank.csv"), "\n\n");
  ExpectBadInput(dir.File("blank.csv"), "empty input");
}

}  // namespace
}  // namespace octocosm
