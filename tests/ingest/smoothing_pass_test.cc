#include "ingest/smoothing_pass.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include "base/error.h"
#include "tests/support/temp_dir.h"
#include "tests/support/thread_rank_group.h"

namespace octocosm {
namespace {

// A snapshot in memory, handed out in chunks of `chunk` particles.
class VectorSource : public ParticleSource {
 public:
  VectorSource(std::vector<double> positions, std::vector<float> given, double box, std::size_t chunk = 777)
      : positions_(std::move(positions)), given_(std::move(given)), chunk_(chunk) {
    header_.format = "test";
    header_.files = {"memory"};
    header_.box_size = box;
    header_.total_count = positions_.size() / 3;
    header_.count_per_type = {header_.total_count};
  }
  const SnapshotHeader& header() const override { return header_; }
  bool Next(ParticleChunk& chunk) override {
    chunk.clear();
    const std::size_t total = positions_.size() / 3;
    if (next_ >= total) return false;
    const std::size_t end = std::min(total, next_ + chunk_);
    chunk.position.assign(positions_.begin() + 3 * next_, positions_.begin() + 3 * end);
    chunk.mass.assign(end - next_, 1.0);
    chunk.type.assign(end - next_, 0);
    if (!given_.empty()) chunk.smoothing.assign(given_.begin() + next_, given_.begin() + end);
    next_ = end;
    ++(positions_only_ ? reads_of_positions_only : reads_of_everything);
    return true;
  }
  void Rewind() override { next_ = 0; }
  std::uint64_t Skip() override {
    const std::size_t total = positions_.size() / 3;
    const std::size_t skipped = std::min(chunk_, total - std::min(next_, total));
    next_ += skipped;
    return skipped;
  }
  void SetPositionsOnly(bool positions_only) override { positions_only_ = positions_only; }
  bool positions_only() const { return positions_only_; }

  // Batches handed out while positions only were asked for, and otherwise.
  int reads_of_positions_only = 0, reads_of_everything = 0;

 private:
  std::vector<double> positions_;
  std::vector<float> given_;
  std::size_t chunk_;
  std::size_t next_ = 0;
  bool positions_only_ = false;
  SnapshotHeader header_;
};

// Clumps, a filament and a sparse background in [0, box)^3, with clumps
// straddling the periodic faces.
std::vector<double> ClusteredPoints(std::size_t n, double box, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  const double centres[3][3] = {{0.02, 0.5, 0.5}, {0.6, 0.97, 0.99}, {0.4, 0.4, 0.3}};
  std::vector<double> points;
  for (std::size_t i = 0; i < n; ++i) {
    double p[3];
    const std::size_t kind = i % 10;
    if (kind < 6) {
      const double* c = centres[kind % 3];
      for (int a = 0; a < 3; ++a) p[a] = c[a] + 0.03 * normal(rng);
    } else if (kind < 8) {
      const double t = uniform(rng);
      p[0] = t;
      p[1] = 0.2 + 0.01 * normal(rng);
      p[2] = 0.7 + 0.01 * normal(rng);
    } else {
      for (double& c : p) c = uniform(rng);
    }
    for (double& c : p) {
      c = box * (c - std::floor(c));
      if (c >= box) c = 0;
      points.push_back(c);
    }
  }
  return points;
}

// The k-th smallest distance from particle i to all particles (itself
// included), minimal image in a periodic box.
double BruteForce(const std::vector<double>& points, std::size_t i, int k, double box) {
  std::vector<double> d;
  for (std::size_t j = 0; j < points.size() / 3; ++j) {
    double s = 0;
    for (int a = 0; a < 3; ++a) {
      double delta = std::abs(points[3 * j + a] - points[3 * i + a]);
      if (box > 0) delta = std::min(delta, box - delta);
      s += delta * delta;
    }
    d.push_back(std::sqrt(s));
  }
  const std::size_t kth = std::min<std::size_t>(static_cast<std::size_t>(k), d.size()) - 1;
  std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(kth), d.end());
  return d[kth];
}

struct Case {
  const char* name;
  double box;
  std::uint64_t budget;  // 0 = the default (everything in memory)
};

void ExpectExact(const Case& c, std::size_t n, int k) {
  const std::vector<double> points = ClusteredPoints(n, c.box > 0 ? c.box : 100.0, 11);
  VectorSource source(points, {}, c.box);
  testing_support::TempDir temp("smoothing-pass");
  SmoothingPassOptions options;
  options.neighbours = k;
  options.box_size = c.box;
  options.memory_budget = c.budget;
  options.temp_dir = temp.path().string();
  options.quiet = true;
  SmoothingPassReport report;
  const auto table = ComputeSmoothingLengths(source, options, &report);
  ASSERT_EQ(table->size(), n);
  EXPECT_EQ(report.searched, n) << c.name;
  double worst = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double truth = BruteForce(points, i, k, c.box);
    const double got = (*table)[i];
    worst = std::max(worst, std::abs(got - truth) / truth);
    ASSERT_NEAR(got, truth, 1e-6 * truth) << c.name << " particle " << i << " at " << points[3 * i] << ","
                                         << points[3 * i + 1] << "," << points[3 * i + 2];
  }
  ::testing::Test::RecordProperty(std::string(c.name) + "_worst_relative_error", std::to_string(worst));
  if (c.budget != 0) {
    EXPECT_GT(report.regions, 1u) << c.name;
  }
  // Regions go through files; their halos leave some sparse particles to
  // the second search.
  EXPECT_EQ(report.spilled, c.budget != 0) << c.name;
  if (c.budget != 0) {
    EXPECT_GT(report.searched_again, 0u) << c.name;
  }
  // Nothing is left in the temporary directory.
  EXPECT_TRUE(std::filesystem::is_empty(temp.path())) << c.name;
}

TEST(SmoothingPass, InMemoryEqualsBruteForceWithoutABox) { ExpectExact({"open", 0, 0}, 4000, 32); }

TEST(SmoothingPass, InMemoryEqualsBruteForceAcrossPeriodicFaces) { ExpectExact({"periodic", 100, 0}, 4000, 32); }

TEST(SmoothingPass, RegionsThroughFilesEqualBruteForce) {
  // 4000 particles at 112 bytes need 448 kB: a budget of 100 kB cuts
  // several regions, one of 20 kB (about 180 particles) many.
  ExpectExact({"regions-open", 0, 100000}, 4000, 32);
  ExpectExact({"regions-periodic", 100, 100000}, 4000, 32);
  ExpectExact({"small-regions-open", 0, 20000}, 4000, 16);
  ExpectExact({"small-regions-periodic", 100, 20000}, 4000, 16);
}

// Out of core the search stays within its budget: each region's buffers are
// freed before the next region is loaded. (They were kept, emptied but not
// freed, and 10^8 particles under --memory 2G peaked at 7 GiB.) Measured in
// a child process, from its resident size when it starts the pass to its
// peak; ASan's quarantine of freed memory would hide what this measures.
TEST(SmoothingPass, RegionsStayWithinTheBudget) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "AddressSanitizer keeps freed memory in quarantine";
#else
  const std::size_t n = 1000000;
  const std::uint64_t budget = 16 << 20;
  const std::vector<double> points = ClusteredPoints(n, 100, 3);
  testing_support::TempDir temp("smoothing-pass-budget");
  int pipe_fds[2];
  ASSERT_EQ(::pipe(pipe_fds), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(pipe_fds[0]);
    VectorSource source(points, {}, 100, 65536);
    SmoothingPassOptions options;
    options.box_size = 100;
    options.memory_budget = budget;
    options.temp_dir = temp.path().string();
    options.quiet = true;
    long start_kib = 0;
    std::ifstream status("/proc/self/status");
    for (std::string line; std::getline(status, line);) {
      if (line.rfind("VmRSS:", 0) == 0) start_kib = std::atol(line.c_str() + 6);
    }
    SmoothingPassReport report;
    ComputeSmoothingLengths(source, options, &report);
    rusage usage{};
    ::getrusage(RUSAGE_SELF, &usage);
    const long result[2] = {usage.ru_maxrss - start_kib, static_cast<long>(report.regions)};
    const bool written = ::write(pipe_fds[1], result, sizeof result) == static_cast<ssize_t>(sizeof result);
    ::_exit(written ? 0 : 1);
  }
  ::close(pipe_fds[1]);
  long result[2] = {0, 0};
  const bool read_all = ::read(pipe_fds[0], result, sizeof result) == static_cast<ssize_t>(sizeof result);
  ::close(pipe_fds[0]);
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(read_all && WIFEXITED(status) && WEXITSTATUS(status) == 0);
  EXPECT_GT(result[1], 8) << "regions";
  // The budget, and a fixed part: the table of lengths (4 MB here), the
  // count grid (8 MiB), the threads' stacks and buffers (measured: 54 MiB in
  // all; without freeing the regions' buffers, 385 MiB).
  EXPECT_LT(result[0], static_cast<long>(budget / 1024) + 48 * 1024) << "KiB grown during the pass";
#endif
}

// Enough particles for the search to cut its tree into blocks built on
// several threads and to sort on several: the same lengths as on one thread,
// and those exact.
TEST(SmoothingPass, SeveralThreadsGiveTheLengthsOfOne) {
  const std::size_t n = 400000;
  const double box = 100;
  const std::vector<double> points = ClusteredPoints(n, box, 5);
  std::vector<std::unique_ptr<SmoothingLengthTable>> tables;
  for (unsigned threads : {1u, 3u}) {
    VectorSource source(points, {}, box, 65536);
    SmoothingPassOptions options;
    options.box_size = box;
    options.threads = threads;
    options.quiet = true;
    tables.push_back(ComputeSmoothingLengths(source, options));
  }
  for (std::size_t i = 0; i < n; ++i) ASSERT_EQ((*tables[0])[i], (*tables[1])[i]) << i;
  for (std::size_t i = 0; i < n; i += 4001) {
    const double truth = BruteForce(points, i, kDefaultNeighbours, box);
    ASSERT_NEAR((*tables[1])[i], truth, 1e-6 * truth) << i;
  }
}

// Processes that share the pass (threads here) each read a share of the
// batches and search their own regions' particles, and each ends with one
// search's lengths, exactly, of the batches it reads (and nothing else): in
// memory and through files, with and without a periodic box, with part of
// the snapshot's own lengths given.
TEST(SmoothingPass, SharedByProcessesEachHoldOneSearchsLengthsOfTheBatchesItReads) {
  const std::size_t n = 6000;
  struct Setting {
    const char* name;
    double box;
    std::uint64_t budget;
  };
  for (const Setting& setting : {Setting{"open", 0, 0}, Setting{"periodic", 100, 0}, Setting{"open-files", 0, 60000},
                                 Setting{"periodic-files", 100, 60000}}) {
    const std::vector<double> points = ClusteredPoints(n, 100, 17);
    std::vector<float> given(n, 0);
    for (std::size_t i = 0; i < n; i += 10) given[i] = 0.5f + static_cast<float>(i % 7);
    testing_support::TempDir temp("smoothing-pass-parts");
    SmoothingPassOptions options;
    options.neighbours = 16;
    options.box_size = setting.box;
    options.memory_budget = setting.budget;
    options.temp_dir = temp.path().string();
    options.quiet = true;
    VectorSource whole_source(points, given, setting.box);
    SmoothingPassReport whole_report;
    const auto whole = ComputeSmoothingLengths(whole_source, options, &whole_report);
    const int batches = whole_source.reads_of_positions_only / whole_report.reads;
    for (int ranks : {2, 3, 5}) {
      SCOPED_TRACE(std::string(setting.name) + ", " + std::to_string(ranks) + " processes");
      std::vector<std::vector<float>> tables(static_cast<std::size_t>(ranks));
      std::vector<int> reads(static_cast<std::size_t>(ranks)), batches_read(static_cast<std::size_t>(ranks));
      std::vector<std::uint64_t> regions(static_cast<std::size_t>(ranks)), again(static_cast<std::size_t>(ranks)),
          searched(static_cast<std::size_t>(ranks));
      testing_support::RunRanks(ranks, [&](RankGroup& group) {
        SmoothingPassOptions mine = options;
        mine.group = &group;
        VectorSource source(points, given, setting.box);
        SmoothingPassReport report;
        const auto table = ComputeSmoothingLengths(source, mine, &report);
        const std::size_t r = static_cast<std::size_t>(group.rank());
        tables[r].assign(table->data(), table->data() + n);
        reads[r] = report.reads;
        batches_read[r] = source.reads_of_positions_only + source.reads_of_everything;
        regions[r] = report.regions;
        again[r] = report.searched_again;
        searched[r] = report.searched;
      });
      // Some particles near their regions' edges are searched again, from reads shared as well.
      EXPECT_GT(std::accumulate(again.begin(), again.end(), std::uint64_t{0}), 0u);
      std::vector<float> combined(n, 0);
      for (std::size_t r = 0; r < tables.size(); ++r) {
        EXPECT_GE(regions[r], std::uint64_t{8} * static_cast<std::uint64_t>(ranks));
        // Each reads its share of the batches in every pass, no more.
        EXPECT_LE(batches_read[r], reads[r] * ((batches + ranks - 1) / ranks)) << "process " << r;
        for (std::size_t i = 0; i < n; ++i) {
          const bool read_here = (i / 777) % static_cast<std::size_t>(ranks) == r;  // VectorSource's batches of 777
          if (read_here) {
            ASSERT_EQ(tables[r][i], (*whole)[i]) << "process " << r << ", particle " << i;
            combined[i] = tables[r][i];
          } else {
            ASSERT_EQ(tables[r][i], 0.0f) << "process " << r << " holds particle " << i << " it does not read";
          }
        }
      }
      // Every particle is read by one process.
      for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(combined[i], (*whole)[i]) << "particle " << i;
      // The searches come out about even, and search each particle once.
      for (std::size_t r = 0; r < searched.size(); ++r) {
        EXPECT_GT(searched[r], n * 9 / 10 / static_cast<std::size_t>(ranks) / 2) << "process " << r;
      }
      EXPECT_EQ(std::accumulate(searched.begin(), searched.end(), std::uint64_t{0}), whole_report.searched);
      EXPECT_TRUE(std::filesystem::is_empty(temp.path()));
    }
  }
}

TEST(SmoothingPass, FewerParticlesThanNeighboursTakeThemAll) { ExpectExact({"few", 0, 0}, 10, 32); }

TEST(SmoothingPass, KeepsTheSnapshotsOwnSmoothingLengths) {
  const std::size_t n = 2000;
  const std::vector<double> points = ClusteredPoints(n, 50, 3);
  std::vector<float> given(n, 0.0f);
  for (std::size_t i = 0; i < n; i += 3) given[i] = 0.5f + static_cast<float>(i) * 1e-3f;
  SmoothingPassOptions options;
  options.box_size = 50;
  options.quiet = true;
  {
    VectorSource source(points, given, 50);
    SmoothingPassReport report;
    const auto table = ComputeSmoothingLengths(source, options, &report);
    EXPECT_EQ(report.given, (n + 2) / 3);
    EXPECT_EQ(report.searched, n - report.given);
    for (std::size_t i = 0; i < n; ++i) {
      if (given[i] > 0) {
        EXPECT_EQ((*table)[i], given[i]);
      } else {
        // The particles with given lengths still count as neighbours.
        EXPECT_NEAR((*table)[i], BruteForce(points, i, 32, 50), 1e-6 * (*table)[i]);
      }
    }
  }
}

TEST(SmoothingPass, TheWrappedSourceCarriesTheTable) {
  const std::vector<double> points = ClusteredPoints(1500, 10, 5);
  SmoothingPassOptions options;
  options.quiet = true;
  auto inner = std::make_unique<VectorSource>(points, std::vector<float>{}, 0.0, 100);
  std::shared_ptr<const SmoothingLengthTable> table = ComputeSmoothingLengths(*inner, options);
  auto source = WithSmoothingLengths(std::move(inner), table);
  for (int round = 0; round < 2; ++round) {
    ParticleChunk chunk;
    std::size_t next = 0;
    while (source->Next(chunk)) {
      ASSERT_EQ(chunk.smoothing.size(), chunk.size());
      for (std::size_t i = 0; i < chunk.size(); ++i) ASSERT_EQ(chunk.smoothing[i], (*table)[next + i]);
      next += chunk.size();
    }
    EXPECT_EQ(next, 1500u);
    EXPECT_TRUE(source->MappableSegments().empty());
    source->Rewind();
  }
}

TEST(SmoothingPass, ReadsPositionsOnlyAndAsksForEveryColumnAfterwards) {
  for (const std::uint64_t budget : {std::uint64_t{0}, std::uint64_t{20000}}) {  // in memory; through files
    SCOPED_TRACE("budget " + std::to_string(budget));
    testing_support::TempDir temp("smoothing-pass-positions");
    SmoothingPassOptions options;
    options.quiet = true;
    options.memory_budget = budget;
    options.temp_dir = temp.path().string();
    auto inner = std::make_unique<VectorSource>(ClusteredPoints(1500, 10, 6), std::vector<float>{}, 0.0, 100);
    VectorSource& counted = *inner;
    std::shared_ptr<const SmoothingLengthTable> table = ComputeSmoothingLengths(counted, options);
    EXPECT_GT(counted.reads_of_positions_only, 0);
    EXPECT_EQ(counted.reads_of_everything, 0);
    EXPECT_FALSE(counted.positions_only());
    // The source with the lengths passes the request on.
    auto source = WithSmoothingLengths(std::move(inner), table);
    source->SetPositionsOnly(true);
    EXPECT_TRUE(counted.positions_only());
  }
}

TEST(SmoothingPass, RefusesBadOptionsAndEmptySnapshots) {
  VectorSource empty({}, {}, 0);
  SmoothingPassOptions options;
  options.quiet = true;
  EXPECT_THROW(ComputeSmoothingLengths(empty, options), Error);
  VectorSource one({1, 2, 3}, {}, 0);
  options.neighbours = 0;
  EXPECT_THROW(ComputeSmoothingLengths(one, options), Error);
  options.neighbours = 32;
  options.box_size = std::nan("");
  EXPECT_THROW(ComputeSmoothingLengths(one, options), Error);
}

}  // namespace
}  // namespace octocosm
