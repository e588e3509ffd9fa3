// Fuzz target: the GADGET binary reader (ingest/snapshot/gadget_source.h),
// format 1 and 2 in either byte order, on one file.
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "tests/fuzz/fuzz_target.h"
#include "tests/fuzz/snapshot_fuzz.h"
#include "tests/ingest/snapshot/gadget_test_file.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  octocosm::ReadOptions options;
  options.format = "gadget";
  octocosm::fuzz::ReadSnapshotBytes(data, size, "snap", options);
  return 0;
}

namespace octocosm::fuzz {
namespace {

// A spec with `npart` particles per type at distinct positions inside the box.
GadgetSpec Particles(const std::array<std::int32_t, 6>& npart) {
  GadgetSpec spec;
  spec.npart = npart;
  std::size_t n = 0;
  for (auto count : npart) n += static_cast<std::size_t>(count);
  for (std::size_t i = 0; i < n; ++i) {
    for (int axis = 0; axis < 3; ++axis) {
      spec.position.push_back(static_cast<double>((i * 37 + static_cast<std::size_t>(axis) * 11) % 97) + 0.5);
      spec.velocity.push_back(static_cast<double>(i) - 3.0 * axis);
    }
    spec.ids.push_back(i + 1);
  }
  return spec;
}

}  // namespace

std::vector<Seed> Seeds(const std::string& shared_data) {
  std::vector<Seed> seeds;
  {  // Format 1, little endian, masses from the table.
    GadgetSpec spec = Particles({0, 5, 0, 0, 0, 0});
    spec.mass_table[1] = 2.5;
    seeds.push_back({"format1-le", EncodeGadget(spec)});
  }
  {  // Format 2, big endian, doubles and 8-byte IDs, a MASS block for the types without a table mass.
    GadgetSpec spec = Particles({3, 4, 0, 0, 2, 0});
    spec.format = 2;
    spec.big_endian = true;
    spec.real_bytes = 8;
    spec.id_bytes = 8;
    spec.mass_table[1] = 1.0;
    spec.mass_block = {0.5, 0.25, 0.125, 3.0, 4.0};
    spec.hsml = {1.0, 2.0, 0.5};
    seeds.push_back({"format2-be-f64", EncodeGadget(spec)});
  }
  {  // Format 2, little endian, gas with smoothing lengths, no velocities.
    GadgetSpec spec = Particles({4, 0, 0, 0, 0, 0});
    spec.format = 2;
    spec.mass_table[0] = 0.75;
    spec.write_velocity = false;
    spec.velocity.clear();
    spec.hsml = {0.1, 0.2, 0.3, 0.4};
    seeds.push_back({"format2-le-gas", EncodeGadget(spec)});
  }
  {  // Format 1, big endian, totals left zero as initial conditions often do.
    GadgetSpec spec = Particles({0, 3, 2, 0, 0, 0});
    spec.big_endian = true;
    spec.mass_table = {0, 1.5, 0.5, 0, 0, 0};
    spec.total = std::array<std::uint32_t, 6>{};
    spec.box = 0;
    seeds.push_back({"format1-be-ics", EncodeGadget(spec)});
  }
  for (auto& seed : SharedDataSeeds(shared_data, "gadget2_ics", [](const std::string&) { return true; })) {
    seeds.push_back(std::move(seed));
  }
  // One file of a two-file set: the reader must refuse it for want of the other.
  for (auto& seed : SharedDataSeeds(shared_data, "gadget2_format2_multifile",
                                    [](const std::string& name) { return name.ends_with(".0"); })) {
    seeds.push_back(std::move(seed));
  }
  return seeds;
}

}  // namespace octocosm::fuzz
