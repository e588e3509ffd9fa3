// A test fixture for ingest runs: a scratch directory with a `tmp` folder for
// ingest's temporary files (so a test can check that none are left behind),
// and ingest options pointing into it; particles written as the raw layout
// "xyz:f64,mass:f64,id:u64", and a clustered set of them.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "base/error.h"
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

// How Clustered() lays its particles out.
struct ClusteredSpec {
  double origin = 0;  // the points fill [origin, origin + size)^3
  double size = 1;
  int halos = 6;
  int mass_cycle = 7;  // masses 1, 2, ..., mass_cycle, 1, ...
  std::uint64_t first_id = 1000;
  std::uint64_t id_step = 3;
};

// Clustered points: a third uniform, the rest in Gaussian halos (sigma
// size/40) taken in turn; the same sequence for the same seed and spec.
inline std::vector<Particle> Clustered(std::size_t n, std::uint64_t seed, const ClusteredSpec& spec) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(0, spec.size);
  std::normal_distribution<double> gauss(0, spec.size / 40);
  std::vector<std::array<double, 3>> centres(static_cast<std::size_t>(spec.halos));
  for (auto& c : centres) c = {uniform(rng), uniform(rng), uniform(rng)};
  std::vector<Particle> particles(n);
  for (std::size_t i = 0; i < n; ++i) {
    Particle& p = particles[i];
    for (std::size_t a = 0; a < 3; ++a) {
      const double t = i % 3 == 0 ? uniform(rng) : centres[i % centres.size()][a] + gauss(rng);
      p.x[a] = spec.origin + std::clamp(t, 0.0, spec.size * 0.999999);
    }
    p.mass = 1.0 + static_cast<double>(i % static_cast<std::size_t>(spec.mass_cycle));
    p.id = spec.first_id + i * spec.id_step;
  }
  return particles;
}

// Expects `run` to throw BadInput whose message holds each of `parts`.
template <typename Run>
void ExpectBadInputFrom(Run run, const std::vector<std::string>& parts) {
  try {
    run();
    ADD_FAILURE() << "no error (expected \"" << parts.back() << "\")";
  } catch (const Error& error) {
    EXPECT_EQ(error.kind(), ErrorKind::kBadInput) << error.what();
    for (const std::string& part : parts) EXPECT_NE(std::string(error.what()).find(part), std::string::npos) << error.what();
  }
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
