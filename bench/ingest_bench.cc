// octocosm-bench-ingest: ingest throughput, CPU time and peak memory.
//
// For each case it generates a clustered snapshot with the scale generator
// (halos with NFW profiles on a filament skeleton plus a background,
// `octocosm synth scale`), then runs `octocosm ingest` on it as a child
// process, so that the child's own peak RSS and CPU time are measured
// (wait4's rusage), and prints one row per case:
//   points, input MB, budget, neighbours, wall s, M points/s, CPU s, CPU use, peak RSS, RSS / budget
// Each case runs once per --neighbours value: the default 32 (leaves'
// smoothing lengths from the 32 nearest neighbours, a pass of its own before
// the rest) and 0 (the density grid's, no pass).
// Default cases: 10^7 and 10^8 points with the default budget,
// and 4x10^7 points (1.1 GB of input) under a 256 MiB budget: input > 4x budget.
//
// Before each run the snapshot's files are dropped from the page cache and
// read once, so that the ingest reads them from the page cache as a snapshot
// just read from disk (one kept from an earlier run with --keep may have left
// the cache, which made the read phase of equal runs differ by a factor of
// two; and how the cache holds a file depends on how it got there, see
// ReadThroughPageCache). --cold skips that: the input then comes from
// wherever it is.
//
// The reference figure is the issue's: PotreeConverter 2.x `-m random` builds
// clustered data at about 2.4 M points/s on these 2-core machines. Given the
// path of a PotreeConverter program (--potree-converter; it is not packaged
// for Debian), the bench also measures it on the same points, written once
// as an uncompressed LAS file (bench/las_export.h), straight after octocosm
// in each case without a budget (PotreeConverter takes none), and prints the
// ratio of the two.
#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <thread>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "bench/las_export.h"
#include "tools/cli_util.h"
#include "synth/scale_generator.h"

extern char** environ;

namespace octocosm {
namespace {

namespace fs = std::filesystem;

struct Case {
  std::uint64_t points;
  std::string memory;  // "" = ingest's default
};

struct ChildUsage {
  double wall = 0, cpu = 0;
  double peak_rss_bytes = 0;
  int status = 0;
};

// Runs the program args[0]; with `quiet`, its standard output goes to /dev/null.
ChildUsage RunChild(const std::vector<std::string>& args, bool quiet = false) {
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const auto start = std::chrono::steady_clock::now();
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  if (quiet) posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  pid_t pid = 0;
  const int spawned = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) throw IoErrorFromErrno(args[0], "starting", spawned);
  ChildUsage usage;
  struct rusage ru {};
  if (wait4(pid, &usage.status, 0, &ru) < 0) throw IoErrorFromErrno(args[0], "waiting for", errno);
  usage.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  usage.cpu = static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
              static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec) / 1e6;
  usage.peak_rss_bytes = static_cast<double>(ru.ru_maxrss) * 1024.0;
  return usage;
}

// Reads every file under `dir` once, into nothing: into the page cache. Each
// file is first written back and dropped from the cache, so that the cache
// holds it as the kernel lays out a file read from disk, not as the
// generator happened to write it: on Linux 6.18 a file read from disk is
// cached in 2 MiB folios that a mapping maps whole, while synth's writes of a
// few hundred KiB leave 4 KiB ones, and a 10^8-point ingest read its mapped
// snapshot from those about 10 % slower (its scattered reads missing the TLB;
// docs/BENCHMARKS.md).
void ReadThroughPageCache(const fs::path& dir) {
  std::vector<char> buffer(std::size_t{4} << 20);
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    const int fd = ::open(entry.path().c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw IoErrorFromErrno(entry.path().string(), "opening", errno);
    // Best effort: where the cache cannot be dropped the read still fills it.
    if (::fdatasync(fd) == 0) ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
    ssize_t got = 0;
    while ((got = ::read(fd, buffer.data(), buffer.size())) > 0) {
    }
    const int read_errno = errno;
    ::close(fd);
    if (got < 0) throw IoErrorFromErrno(entry.path().string(), "reading", read_errno);
  }
}

std::uint64_t DirectoryBytes(const fs::path& dir) {
  std::uint64_t total = 0;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.is_regular_file()) total += entry.file_size();
  }
  return total;
}

// What an ingest holds besides its budget whatever its size: the program,
// its libraries, thread stacks, the writer's queue (docs/INGEST.md).
constexpr double kFixedOverheadBytes = 96.0 * 1024 * 1024;

}  // namespace
}  // namespace octocosm

int main(int argc, char** argv) {
  using namespace octocosm;
  std::string dir = "octocosm-ingest-bench";
  std::string octocosm_path = (fs::path(argv[0]).parent_path() / ".." / "tools" / "octocosm").string();
  std::vector<std::string> case_texts = {"1e7", "1e8", "4e7@256M"};
  bool keep = false;
  bool cold = false;
  std::string potree_converter;
  std::vector<int> neighbour_modes = {32, 0};
  CLI::App app{"octocosm-bench-ingest: ingest throughput, CPU time and peak RSS on generated clustered data"};
  app.add_option("--dir", dir, "scratch directory (removed afterwards)")->default_val(dir);
  app.add_option("--octocosm", octocosm_path, "the octocosm program to measure")->default_val(octocosm_path);
  app.add_option("--case", case_texts, "cases POINTS[@MEMORY], e.g. 1e7 1e8 4e7@256M")->default_val(case_texts);
  app.add_flag("--keep", keep, "keep the generated snapshots and stores");
  app.add_flag("--cold", cold, "do not read the input into the page cache before each run");
  app.add_option("--neighbours", neighbour_modes, "ingest --neighbours values to run each case with (0: no neighbour pass)")
      ->default_val(neighbour_modes);
  app.add_option("--potree-converter", potree_converter,
                 "also run this PotreeConverter 2.x program (-m random) on the same points, written as LAS, in each "
                 "case without a budget, and print octocosm's throughput against it")
      ->check(CLI::ExistingFile);
  CLI11_PARSE(app, argc, argv);

  try {
    std::vector<Case> cases;
    for (const std::string& text : case_texts) {
      const auto at = text.find('@');
      Case c;
      c.points = static_cast<std::uint64_t>(std::stod(text.substr(0, at)));
      if (at != std::string::npos) c.memory = text.substr(at + 1);
      cases.push_back(c);
    }
    fs::create_directories(dir);
    std::printf("octocosm-bench-ingest: %s on %u cores; %s\n", octocosm_path.c_str(), std::thread::hardware_concurrency(),
                cold ? "input read from wherever it is (--cold)"
                     : "input dropped from the page cache and read once before each run");
    std::fflush(stdout);  // before the children write theirs
    int over_budget = 0;  // cases with a budget whose peak RSS exceeded it plus the fixed overhead
    std::printf("%12s %10s %9s %10s %9s %11s %8s %7s %11s %10s %10s\n", "points", "input MB", "budget", "neighbours",
                "wall s", "M points/s", "CPU s", "CPU use", "peak RSS", "RSS/budget", "vs 2.4M/s");
    for (const Case& c : cases) {
      const fs::path snapshots = fs::path(dir) / ("snap-" + std::to_string(c.points));
      if (!fs::exists(snapshots)) {
        synth::ScaleOptions options;
        options.output_directory = snapshots.string();
        options.particle_count = c.points;
        options.seed = 7;
        synth::RunScaleGenerator(options, nullptr);
      }
      const std::uint64_t input_bytes = DirectoryBytes(snapshots);
      const fs::path store = fs::path(dir) / "store";
      std::vector<double> rates;  // per neighbour mode
      for (const int neighbours : neighbour_modes) {
        fs::remove_all(store);
        std::vector<std::string> args = {octocosm_path, "ingest", (snapshots / "snap").string(), "-o", store.string(),
                                         "-q", "--neighbours", std::to_string(neighbours)};
        if (!c.memory.empty()) {
          args.push_back("--memory");
          args.push_back(c.memory);
        }
        if (!cold) ReadThroughPageCache(snapshots);
        const ChildUsage u = RunChild(args);
        if (!WIFEXITED(u.status) || WEXITSTATUS(u.status) != 0) {
          std::fprintf(stderr, "octocosm ingest failed for %llu points\n", static_cast<unsigned long long>(c.points));
          return 1;
        }
        const double budget = c.memory.empty() ? 0.0 : static_cast<double>(ParseByteSize(c.memory, "--case"));
        if (budget > 0 && u.peak_rss_bytes > budget + kFixedOverheadBytes) ++over_budget;
        const double rate = static_cast<double>(c.points) / u.wall / 1e6;
        rates.push_back(rate);
        std::printf("%12llu %10.0f %9s %10d %9.2f %11.2f %8.2f %6.0f%% %11s %10s %9.2fx\n",
                    static_cast<unsigned long long>(c.points), static_cast<double>(input_bytes) / 1e6,
                    c.memory.empty() ? "default" : c.memory.c_str(), neighbours, u.wall, rate, u.cpu,
                    100.0 * u.cpu / u.wall, HumanBytes(u.peak_rss_bytes).c_str(),
                    budget > 0 ? (std::to_string(u.peak_rss_bytes / budget).substr(0, 4)).c_str() : "-", rate / 2.4);
        std::fflush(stdout);
        fs::remove_all(store);
      }
      if (!potree_converter.empty() && c.memory.empty()) {
        const fs::path las_dir = fs::path(dir) / ("las-" + std::to_string(c.points));
        const fs::path las = las_dir / "snap.las";
        if (!fs::exists(las)) {
          fs::create_directories(las_dir);
          ExportLas((snapshots / "snap").string(), las.string());
        }
        const fs::path potree_out = fs::path(dir) / "potree";
        fs::remove_all(potree_out);
        if (!cold) ReadThroughPageCache(las_dir);
        const ChildUsage p =
            RunChild({potree_converter, las.string(), "-o", potree_out.string(), "-m", "random"}, /*quiet=*/true);
        if (!WIFEXITED(p.status) || WEXITSTATUS(p.status) != 0) {
          std::fprintf(stderr, "%s failed for %llu points\n", potree_converter.c_str(),
                       static_cast<unsigned long long>(c.points));
          return 1;
        }
        const double potree_rate = static_cast<double>(c.points) / p.wall / 1e6;
        std::printf("%12s PotreeConverter -m random on the same points: %.2f s, %.2f M points/s, CPU %.2f s, "
                    "peak RSS %s; octocosm",
                    "", p.wall, potree_rate, p.cpu, HumanBytes(p.peak_rss_bytes).c_str());
        for (std::size_t m = 0; m < rates.size(); ++m) {
          std::printf("%s %.2fx with --neighbours %d", m ? "," : "", rates[m] / potree_rate, neighbour_modes[m]);
        }
        std::printf("\n");
        std::fflush(stdout);
        fs::remove_all(potree_out);
        if (!keep) fs::remove_all(las_dir);
      }
      if (!keep) fs::remove_all(snapshots);
    }
    if (!keep) fs::remove_all(dir);
    std::printf("memory: %s\n", over_budget == 0
                                    ? "every case with a budget peaked within it plus the fixed overhead (96 MiB)"
                                    : (std::to_string(over_budget) +
                                       " case(s) with a budget peaked above it plus the fixed overhead (96 MiB): FAILED")
                                          .c_str());
    if (over_budget > 0) return 1;
  } catch (const Error& e) {
    std::fprintf(stderr, "octocosm-bench-ingest: %s\n", e.what());
    return 1;
  }
  return 0;
}
