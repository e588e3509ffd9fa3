// A test fixture for ingest runs: a scratch directory with a `tmp` folder for
// ingest's temporary files (so a test can check that none are left behind),
// and ingest options pointing into it; and particles written as the raw
// layout "xyz:f64,mass:f64,id:u64".
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "ingest/ingest.h"
#include "tests/support/temp_dir.h"

namespace octocosm::testing_support {

struct Particle {
  double x[3];
  double mass;
  std::uint64_t id;
};

// Writes `particles` to `path` in the raw layout "xyz:f64,mass:f64,id:u64"; returns the path.
inline std::string WriteRaw(const std::filesystem::path& path, const std::vector<Particle>& particles) {
  std::ofstream out(path, std::ios::binary);
  for (const Particle& p : particles) {
    out.write(reinterpret_cast<const char*>(p.x), sizeof p.x);
    out.write(reinterpret_cast<const char*>(&p.mass), sizeof p.mass);
    out.write(reinterpret_cast<const char*>(&p.id), sizeof p.id);
  }
  return path.string();
}

class IngestFixture : public ::testing::Test {
 protected:
  IngestFixture() { std::filesystem::create_directories(dir_ / "tmp"); }

  // Quiet, 4 KiB pages, output `out` and temporary files in the scratch directory.
  IngestOptions Options(std::vector<std::string> inputs, const std::string& out) const {
    IngestOptions o;
    o.inputs = std::move(inputs);
    o.output = (dir_ / out).string();
    o.temp_dir = (dir_ / "tmp").string();
    o.quiet = true;
    o.page_size = 4096;
    return o;
  }
  bool TempIsEmpty() const { return std::filesystem::is_empty(dir_ / "tmp"); }

  TempDir scratch_{"ingest-test"};
  const std::filesystem::path dir_ = scratch_.path();
};

}  // namespace octocosm::testing_support
