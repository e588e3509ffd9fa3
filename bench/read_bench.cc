// octocosm-bench-read: reading a snapshot through its ParticleSource, for an
// HDF5 snapshot both in this process and through the reader process that
// OpenSnapshot starts for it (ReadOptions::isolate_hdf5,
// docs/INPUT_FORMATS.md), in alternating runs:
//   open   OpenSnapshot: for HDF5 through the reader, starting it and the walk
//   read   every chunk through Next()
// With --hold MiB, the process first fills that much memory and rewrites it
// after each open, as an ingest holding an epoch would: the cost of starting
// the reader does not grow with it (a fork() would copy its page tables and
// make every page copy-on-write).
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {
namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

void ReadOnce(const std::string& snapshot, bool isolated, std::vector<char>& held) {
  ReadOptions options;
  options.isolate_hdf5 = isolated;
  const auto start = Clock::now();
  const auto source = OpenSnapshot(snapshot, options);
  for (std::size_t i = 0; i < held.size(); i += 4096) held[i] = static_cast<char>(held[i] + 1);
  const double open = Seconds(start);
  const auto read_start = Clock::now();
  ParticleChunk chunk;
  std::uint64_t particles = 0;
  while (source->Next(chunk)) particles += chunk.size();
  const double read = Seconds(read_start);
  std::printf("%-11s %10.2f %9.3f %12llu %12.1f\n", isolated ? "reader" : "in-process", 1e3 * open, read,
              static_cast<unsigned long long>(particles), read > 0 ? static_cast<double>(particles) / read / 1e6 : 0.0);
}

}  // namespace
}  // namespace octocosm

int main(int argc, char** argv) {
  CLI::App app{"octocosm-bench-read: a snapshot read in this process and, for HDF5, through its reader process"};
  std::string snapshot;
  int repeats = 3;
  std::size_t hold_mib = 0;
  app.add_option("snapshot", snapshot, "snapshot file (any format OpenSnapshot reads)")->required();
  app.add_option("--repeats", repeats, "alternating runs of each mode")->default_val(3);
  app.add_option("--hold", hold_mib, "MiB of memory to hold and rewrite after each open")->default_val(0);
  CLI11_PARSE(app, argc, argv);
  try {
    std::vector<char> held(hold_mib << 20, 1);
    std::printf("%-11s %10s %9s %12s %12s\n", "mode", "open ms", "read s", "particles", "M/s");
    for (int r = 0; r < repeats; ++r) {
      octocosm::ReadOnce(snapshot, true, held);
      octocosm::ReadOnce(snapshot, false, held);
    }
  } catch (const octocosm::Error& e) {
    std::fprintf(stderr, "octocosm-bench-read: %s\n", e.what());
    return 1;
  }
  return 0;
}
