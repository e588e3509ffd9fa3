// Fuzz target: the HDF5 snapshot reader (ingest/snapshot/hdf5_source.h),
// GADGET-4 / AREPO and SWIFT layouts, on one file. libhdf5 parses the file's
// structure (superblock, object headers, B-trees, heaps, filters); the
// fuzzer reaches our checks of attributes, shapes and values through it.
//
// The reader runs in this process (ReadOptions::isolate_hdf5 off), not in
// the reader process that OpenSnapshot normally has libhdf5 run in:
// libFuzzer measures coverage in this process only, and a crash inside
// libhdf5 is then seen with its stack (docs/TESTING.md). With
// OCTOCOSM_FUZZ_HDF5_ISOLATED=1 the reader isolates as it does for users,
// and every input must end in particles or an Error (ctest
// fuzz_hdf5_isolated).
#include <hdf5.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "tests/fuzz/fuzz_target.h"
#include "tests/fuzz/snapshot_fuzz.h"
#include "tests/support/hdf5_writer.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const bool isolated = [] {
    const char* value = std::getenv("OCTOCOSM_FUZZ_HDF5_ISOLATED");
    return value != nullptr && std::string(value) == "1";
  }();
  octocosm::ReadOptions options;
  options.format = "hdf5";
  options.isolate_hdf5 = isolated;
  octocosm::fuzz::ReadSnapshotBytes(data, size, "snap.hdf5", options);
  return 0;
}

namespace octocosm::fuzz {
namespace {

using testing_support::Hdf5Writer;

// The particles of one type: distinct positions inside a box of 100.
void WriteParticles(Hdf5Writer& w, const char* group, int n, std::uint64_t first_id, bool masses,
                    const char* smoothing_name) {
  std::vector<double> coordinates;
  std::vector<float> velocities, mass, smoothing;
  std::vector<std::uint64_t> ids;
  for (int i = 0; i < n; ++i) {
    for (int axis = 0; axis < 3; ++axis) {
      coordinates.push_back(static_cast<double>((i * 29 + axis * 7) % 90) + 0.25);
      velocities.push_back(static_cast<float>(axis - i));
    }
    ids.push_back(first_id + static_cast<std::uint64_t>(i));
    mass.push_back(0.5f + static_cast<float>(i));
    smoothing.push_back(0.125f * static_cast<float>(i + 1));
  }
  const std::string prefix = std::string(group) + "/";
  w.Dataset(prefix + "Coordinates", H5T_NATIVE_DOUBLE, coordinates, 3);
  w.Dataset(prefix + "Velocities", H5T_NATIVE_FLOAT, velocities, 3);
  w.Dataset(prefix + "ParticleIDs", H5T_NATIVE_UINT64, ids, 1);
  if (masses) w.Dataset(prefix + "Masses", H5T_NATIVE_FLOAT, mass, 1);
  if (smoothing_name != nullptr) w.Dataset(prefix + smoothing_name, H5T_NATIVE_FLOAT, smoothing, 1);
}

// GADGET-4 / AREPO: gas with masses and smoothing lengths, dark matter with a table mass.
std::string Gadget4Seed(const std::string& path, bool chunked) {
  {
    Hdf5Writer w(path, chunked);
    w.Attribute<std::uint32_t>("Header", "NumPart_ThisFile", H5T_NATIVE_UINT32, {3, 5});
    w.Attribute<std::uint64_t>("Header", "NumPart_Total", H5T_NATIVE_UINT64, {3, 5});
    w.Attribute<std::uint32_t>("Header", "NumPart_Total_HighWord", H5T_NATIVE_UINT32, {0, 0});
    w.Attribute<double>("Header", "MassTable", H5T_NATIVE_DOUBLE, {0.0, 4.0});
    w.Attribute<std::int32_t>("Header", "NumFilesPerSnapshot", H5T_NATIVE_INT32, {1});
    w.Attribute<double>("Header", "Time", H5T_NATIVE_DOUBLE, {0.25});
    w.Attribute<double>("Header", "Redshift", H5T_NATIVE_DOUBLE, {3.0});
    w.Attribute<double>("Header", "BoxSize", H5T_NATIVE_DOUBLE, {100.0});
    w.Attribute<double>("Header", "Omega0", H5T_NATIVE_DOUBLE, {0.31});
    w.Attribute<double>("Header", "OmegaLambda", H5T_NATIVE_DOUBLE, {0.69});
    w.Attribute<double>("Header", "HubbleParam", H5T_NATIVE_DOUBLE, {0.68});
    w.Attribute<std::int32_t>("Header", "Flag_DoublePrecision", H5T_NATIVE_INT32, {1});
    WriteParticles(w, "PartType0", 3, 1, true, "SmoothingLength");
    WriteParticles(w, "PartType1", 5, 4, false, nullptr);
  }
  return ReadFileString(path);
}

// SWIFT: per-axis box, the cosmology in its own group, SmoothingLengths.
std::string SwiftSeed(const std::string& path) {
  {
    Hdf5Writer w(path, false);
    w.Attribute<std::uint64_t>("Header", "NumPart_ThisFile", H5T_NATIVE_UINT64, {4, 2});
    w.Attribute<std::uint64_t>("Header", "NumPart_Total", H5T_NATIVE_UINT64, {4, 2});
    w.Attribute<double>("Header", "BoxSize", H5T_NATIVE_DOUBLE, {100, 100, 100});
    w.Attribute<double>("Header", "Time", H5T_NATIVE_DOUBLE, {0.5});
    w.Attribute<std::int32_t>("Header", "NumFilesPerSnapshot", H5T_NATIVE_INT32, {1});
    w.Attribute<double>("Cosmology", "Redshift", H5T_NATIVE_DOUBLE, {1.0});
    w.Attribute<double>("Cosmology", "Scale-factor", H5T_NATIVE_DOUBLE, {0.5});
    w.Attribute<double>("Cosmology", "Omega_m", H5T_NATIVE_DOUBLE, {0.3});
    w.Attribute<double>("Cosmology", "h", H5T_NATIVE_DOUBLE, {0.68});
    w.Attribute<std::int32_t>("Cosmology", "Cosmological run", H5T_NATIVE_INT32, {1});
    w.Attribute<std::int32_t>("Code", "Version", H5T_NATIVE_INT32, {1});
    w.Attribute<float>("HydroScheme", "Kernel target N_ngb", H5T_NATIVE_FLOAT, {48.0f});
    w.Attribute<float>("HydroScheme", "Kernel eta", H5T_NATIVE_FLOAT, {1.2348f});
    WriteParticles(w, "PartType0", 4, 1, true, "SmoothingLengths");
    WriteParticles(w, "PartType1", 2, 5, true, nullptr);
  }
  return ReadFileString(path);
}

}  // namespace

std::vector<Seed> Seeds(const std::string& shared_data) {
  const std::string path = (ScratchDirectory() / "seed.hdf5").string();
  std::vector<Seed> seeds = {{"gadget4.hdf5", Gadget4Seed(path, false)},
                             {"gadget4-chunked.hdf5", Gadget4Seed(path, true)},
                             {"swift.hdf5", SwiftSeed(path)}};
  // The time series repeats one layout: its first and last snapshots suffice.
  for (auto& seed : SharedDataSeeds(shared_data, "gadget4_hdf5_galaxy_collision_timeseries", [](const std::string& name) {
         return name == "snapshot_000.hdf5" || name == "snapshot_020.hdf5";
       })) {
    seeds.push_back(std::move(seed));
  }
  return seeds;
}

}  // namespace octocosm::fuzz
