// octocosm-bench-query: box-query latency against a brute-force scan.
//
// Generates a clustered snapshot (synth scale), ingests it, then for boxes of
// several sizes (edge = box fraction x the cube), centred on randomly chosen
// particles, measures:
//   query   RunQuery at full detail (the deepest level, i.e. every leaf): the
//           exact particles in the box, positions only
//   scan    a brute-force scan of the original snapshot files for the same box
// each COLD (store or snapshot files dropped from the page cache with
// posix_fadvise DONTNEED first) and WARM (run again at once), and prints the
// times, blocks and bytes the query read, and scan time / query time.
#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "index/dataset.h"
#include "ingest/ingest.h"
#include "ingest/snapshot/snapshot_source.h"
#include "query/query.h"
#include "query/region.h"
#include "synth/scale_generator.h"
#include "tools/cli_util.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double Millis(Clock::time_point since) { return std::chrono::duration<double, std::milli>(Clock::now() - since).count(); }

void DropFromPageCache(const std::vector<std::string>& files) {
  for (const std::string& file : files) {
    const int fd = ::open(file.c_str(), O_RDONLY);
    if (fd < 0) continue;
    ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
    ::close(fd);
  }
}

struct Box {
  std::array<double, 3> lo, hi;
};

std::uint64_t ScanSnapshot(const std::string& snapshot, const Box& box) {
  ReadOptions options;
  options.read_velocity = false;
  options.read_id = false;
  auto source = OpenSnapshot(snapshot, options);
  ParticleChunk chunk;
  std::uint64_t inside = 0;
  while (source->Next(chunk)) {
    for (std::size_t i = 0; i < chunk.size(); ++i) {
      const double* p = &chunk.position[3 * i];
      inside += p[0] >= box.lo[0] && p[0] < box.hi[0] && p[1] >= box.lo[1] && p[1] < box.hi[1] && p[2] >= box.lo[2] &&
                p[2] < box.hi[2];
    }
  }
  return inside;
}

}  // namespace
}  // namespace octocosm

int main(int argc, char** argv) {
  using namespace octocosm;
  std::string dir = "octocosm-query-bench";
  double points = 1e7;
  std::vector<double> fractions = {0.01, 0.03, 0.1, 0.3};
  int trials = 3;
  CLI::App app{"octocosm-bench-query: box-query latency, cold and warm, against a brute-force scan of the snapshot"};
  app.add_option("--dir", dir, "scratch directory (removed afterwards)")->default_val(dir);
  app.add_option("--points", points, "particles in the generated snapshot")->default_val(points);
  app.add_option("--fractions", fractions, "box edges as fractions of the cube")->default_val(fractions);
  app.add_option("--trials", trials, "boxes per size (random centres on particles)")->default_val(trials);
  CLI11_PARSE(app, argc, argv);
  try {
    fs::remove_all(dir);
    synth::ScaleOptions scale;
    scale.output_directory = (fs::path(dir) / "snap").string();
    scale.particle_count = static_cast<std::uint64_t>(points);
    scale.seed = 11;
    synth::RunScaleGenerator(scale, nullptr);
    const std::string snapshot = (fs::path(scale.output_directory) / "snap").string();
    const std::vector<std::string> files = OpenSnapshot(snapshot, {})->header().files;

    IngestOptions ingest;
    ingest.inputs = {snapshot};
    ingest.output = (fs::path(dir) / "store").string();
    ingest.quiet = true;
    Ingest(ingest);
    const Dataset dataset = Dataset::Open(ingest.output);
    const Cube& cube = dataset.cube(0);
    int depth = 0;
    dataset.store().Scan(0, 0, ~std::uint64_t{0}, [&](const IndexEntry& e) {
      depth = std::max(depth, NodeKey::FromValue(e.key).level());
      return true;
    });
    std::printf("octocosm-bench-query: %.0f particles, store depth %d, queries at level %d (every leaf: exact)\n", points,
                depth, depth);
    std::printf("%8s %10s %7s %10s %10s %10s %10s %10s %9s %9s\n", "edge", "points", "blocks", "read", "query cold",
                "query warm", "scan cold", "scan warm", "cold x", "warm x");

    // Box centres on particles, so boxes sit where the data is.
    std::vector<std::array<double, 3>> centres;
    {
      auto source = OpenSnapshot(snapshot, {});
      ParticleChunk chunk;
      std::mt19937_64 rng(5);
      while (source->Next(chunk) && centres.size() < 64) {
        const std::size_t i = rng() % chunk.size();
        centres.push_back({chunk.position[3 * i], chunk.position[3 * i + 1], chunk.position[3 * i + 2]});
      }
    }
    for (double fraction : fractions) {
      for (int t = 0; t < trials; ++t) {
        const auto& c = centres[static_cast<std::size_t>(t) % centres.size()];
        const double half = fraction * cube.size / 2;
        // Clamp inside the cube so the brute-force filter and the query agree without periodic images.
        Box box;
        for (int a = 0; a < 3; ++a) {
          const double lo = std::clamp(c[a] - half, cube.origin[a], cube.origin[a] + cube.size - 2 * half);
          box.lo[a] = lo;
          box.hi[a] = lo + 2 * half;
        }
        const auto region = MakeBoxRegion(box.lo, box.hi, cube);
        QueryOptions options;
        options.level = depth;
        double query_ms[2], scan_ms[2];
        QueryStats stats;
        std::uint64_t returned = 0, scanned = 0;
        for (int warm = 0; warm < 2; ++warm) {
          if (!warm) dataset.store().DropCaches();
          auto start = Clock::now();
          stats = RunQuery(dataset, *region, options, [](const QueryBatch&) {});
          query_ms[warm] = Millis(start);
          returned = stats.points_returned;
          if (!warm) DropFromPageCache(files);
          start = Clock::now();
          scanned = ScanSnapshot(snapshot, box);
          scan_ms[warm] = Millis(start);
        }
        std::printf("%8.2f %10llu %7llu %10s %9.1fms %9.1fms %9.1fms %9.1fms %8.1fx %8.1fx%s\n", fraction,
                    static_cast<unsigned long long>(returned), static_cast<unsigned long long>(stats.reads.blocks),
                    HumanBytes(static_cast<double>(stats.reads.bytes)).c_str(), query_ms[0], query_ms[1], scan_ms[0],
                    scan_ms[1], scan_ms[0] / query_ms[0], scan_ms[1] / query_ms[1],
                    returned == scanned ? "" : "  (counts differ at the box faces: quantization)");
        std::fflush(stdout);
      }
    }
    fs::remove_all(dir);
  } catch (const Error& e) {
    std::fprintf(stderr, "octocosm-bench-query: %s\n", e.what());
    return 1;
  }
  return 0;
}
