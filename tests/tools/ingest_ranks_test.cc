// mpirun -n P octocosm ingest (tools/ingest_ranks.h): on 2 and 4 ranks, more
// than this machine has cores, the store equals the one a single process
// writes from the same snapshots, block for block, manifest for manifest;
// a rank that fails ends the whole ingest with its error and leaves nothing.
// Runs where Open MPI is installed (label mpi).
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "index/dataset.h"
#include "index/id_index.h"
#include "storage/coding.h"
#include "storage/store_reader.h"
#include "tests/ingest/store_check.h"
#include "tests/support/program_run.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using testing_support::FirstDifference;
using testing_support::CheckTree;
using testing_support::ProgramRun;
using testing_support::RunCommand;

// mpirun may run as root in containers and CI; the shared-memory transport
// copies through its own buffers where the kernel forbids cross-process reads.
// Under the sanitizers the ranks run without LeakSanitizer: Open MPI's
// components keep allocations to the end from modules they unload in
// MPI_Finalize, which LSan can neither attribute nor so suppress. The same
// ingest runs under LSan in the single process of each test.
const std::string kMpiEnvironment =
    "OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=none "
    "OMPI_MCA_rmaps_base_oversubscribe=1 ASAN_OPTIONS=detect_leaks=0:abort_on_error=1";

class IngestRanksTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const ProgramRun synth = Run(std::string(OCTOCOSM_BINARY) + " synth pm -q -N 20 --outputs 6 --steps 12 -o " +
                                 (dir_.path() / "snapshots").string());
    ASSERT_EQ(synth.status, 0) << synth.Describe();
    for (const auto& entry : fs::directory_iterator(dir_.path() / "snapshots")) inputs_.push_back(entry.path().string());
    std::sort(inputs_.begin(), inputs_.end());
    ASSERT_EQ(inputs_.size(), 6u);
  }

  ProgramRun Run(const std::string& command, const std::string& environment = "") const {
    return RunCommand(command, 300, dir_.path() / "log.txt", environment);
  }

  // octocosm ingest of the snapshots into `store`, on `ranks` MPI ranks (0: no mpirun).
  ProgramRun Ingest(const std::string& store, int ranks) const {
    std::string command = ranks > 0 ? std::string(MPIEXEC) + " -n " + std::to_string(ranks) + " " : std::string();
    command += std::string(OCTOCOSM_BINARY) + " ingest -q -n 400 --neighbours 8 --memory 64M -o " + store;
    for (const std::string& input : inputs_) command += " " + input;
    return Run(command, ranks > 0 ? kMpiEnvironment : "");
  }

  testing_support::TempDir dir_{"ingest-ranks"};
  std::vector<std::string> inputs_;
};

// The blocks of the ID index's store, epoch by epoch.
std::vector<std::vector<Bytes>> IdIndexBlocks(const std::string& store) {
  const StoreReader ids = StoreReader::Open(store + "/ids");
  std::vector<std::vector<Bytes>> blocks(ids.epoch_count());
  for (std::uint32_t e = 0; e < ids.epoch_count(); ++e) {
    ids.Scan(e, 0, ~std::uint64_t{0}, [&](const IndexEntry& entry) {
      blocks[e].push_back(ids.ReadBlock({e, entry.key}));
      return true;
    });
  }
  return blocks;
}

// Every ID of `expected` (by its leaves) is found in the same leaf through
// `store`'s ID index, and an ID in no epoch is not found.
std::string FirstIdIndexDifference(const Dataset& store, const testing_support::TreeCheck& expected, std::uint32_t epoch) {
  const IdIndexReader ids(store.id_index_directory());
  std::vector<std::uint64_t> wanted;
  for (const auto& [id, point] : expected.leaf_points) wanted.push_back(id);
  wanted.push_back(~std::uint64_t{0} - 7);  // in no epoch
  const std::vector<std::optional<NodeKey>> found = ids.FindAll(epoch, wanted);
  for (std::size_t i = 0; i + 1 < wanted.size(); ++i) {
    if (!found[i] || *found[i] != expected.leaf_points.at(wanted[i]).leaf) return "ID " + std::to_string(wanted[i]);
  }
  return found.back() ? "an ID in no epoch found" : "";
}

TEST_F(IngestRanksTest, TwoAndFourRanksWriteTheStoreOneProcessWrites) {
  const std::string single = (dir_.path() / "single").string();
  const ProgramRun one = Ingest(single, 0);
  ASSERT_EQ(one.status, 0) << one.Describe();
  const Dataset expected = Dataset::Open(single);
  ASSERT_EQ(expected.epoch_count(), 6u);
  for (int ranks : {2, 4}) {
    SCOPED_TRACE(std::to_string(ranks) + " ranks");
    const std::string store = (dir_.path() / ("ranks-" + std::to_string(ranks))).string();
    const ProgramRun run = Ingest(store, ranks);
    ASSERT_EQ(run.status, 0) << run.Describe();
    EXPECT_NE(run.output.find("on " + std::to_string(ranks) + " MPI ranks"), std::string::npos) << run.output;
    const Dataset got = Dataset::Open(store);
    ASSERT_EQ(got.epoch_count(), expected.epoch_count());
    // The dataset manifest: cubes, counts, links' fits, snapshot headers.
    EXPECT_EQ(got.store().dataset(), expected.store().dataset());
    EXPECT_EQ(got.store().attribute_schema(), expected.store().attribute_schema());
    for (std::uint32_t e = 0; e < got.epoch_count(); ++e) {
      const testing_support::TreeCheck want = CheckTree(expected, e);
      EXPECT_EQ(FirstDifference(CheckTree(got, e), want), "") << "epoch " << e;
      EXPECT_EQ(FirstIdIndexDifference(got, want, e), "") << "epoch " << e;
      EXPECT_EQ(got.store().epochs()[e].time, expected.store().epochs()[e].time);
    }
    // Byte for byte too: the ID index numbers its leaves in key order.
    EXPECT_TRUE(IdIndexBlocks(store) == IdIndexBlocks(single)) << "the ID index's blocks differ";
    const ProgramRun verify = Run(std::string(OCTOCOSM_BINARY) + " verify " + store);
    EXPECT_EQ(verify.status, 0) << verify.Describe();
    // Nothing but the store is left in the output.
    for (const auto& entry : fs::directory_iterator(store)) {
      const std::string name = entry.path().filename();
      EXPECT_TRUE(name == "manifest.json" || name == "ids" || name.rfind("epoch-", 0) == 0) << name;
    }
  }
}

// The blocks of a store's epoch, by key.
std::map<std::uint64_t, Bytes> EpochBlocks(const Dataset& store, std::uint32_t epoch) {
  std::map<std::uint64_t, Bytes> blocks;
  store.store().Scan(epoch, 0, ~std::uint64_t{0}, [&](const IndexEntry& entry) {
    blocks[entry.key] = store.store().ReadBlock({epoch, entry.key});
    return true;
  });
  return blocks;
}

// One epoch is spread over the ranks (ingest/epoch_domains.h): small
// batches give every rank a share to read, small nodes many domains.
TEST_F(IngestRanksTest, OneEpochSpreadOverTwoAndFourRanksIsTheStoreOneProcessWrites) {
  const std::string snapshot = inputs_.back();
  for (const std::string neighbours : {"0", "8"}) {
    SCOPED_TRACE("--neighbours " + neighbours);
    auto ingest = [&](const std::string& store, int ranks) {
      std::string command = ranks > 0 ? std::string(MPIEXEC) + " -n " + std::to_string(ranks) + " " : std::string();
      command += std::string(OCTOCOSM_BINARY) + " ingest -q -n 200 --chunk-particles 700 --memory 64M --neighbours " +
                 neighbours + " -o " + store + " " + snapshot;
      return Run(command, ranks > 0 ? kMpiEnvironment : "");
    };
    const std::string single = (dir_.path() / ("single-" + neighbours)).string();
    const ProgramRun one = ingest(single, 0);
    ASSERT_EQ(one.status, 0) << one.Describe();
    const Dataset expected = Dataset::Open(single);
    const std::map<std::uint64_t, Bytes> want = EpochBlocks(expected, 0);
    ASSERT_GT(want.size(), 20u);
    for (int ranks : {2, 4}) {
      SCOPED_TRACE(std::to_string(ranks) + " ranks");
      const std::string store = (dir_.path() / ("spread-" + neighbours + "-" + std::to_string(ranks))).string();
      const ProgramRun run = ingest(store, ranks);
      ASSERT_EQ(run.status, 0) << run.Describe();
      const Dataset got = Dataset::Open(store);
      ASSERT_EQ(got.epoch_count(), 1u);
      EXPECT_EQ(got.store().dataset(), expected.store().dataset());
      const testing_support::TreeCheck tree = CheckTree(expected, 0);
      EXPECT_EQ(FirstDifference(CheckTree(got, 0), tree), "");
      EXPECT_EQ(FirstIdIndexDifference(got, tree, 0), "");
      EXPECT_TRUE(IdIndexBlocks(store) == IdIndexBlocks(single)) << "the ID index's blocks differ";
      const std::map<std::uint64_t, Bytes> blocks = EpochBlocks(got, 0);
      EXPECT_EQ(blocks.size(), want.size());
      EXPECT_TRUE(blocks == want) << "the blocks differ";
      const ProgramRun verify = Run(std::string(OCTOCOSM_BINARY) + " verify " + store);
      EXPECT_EQ(verify.status, 0) << verify.Describe();
      for (const auto& entry : fs::directory_iterator(store)) {
        const std::string name = entry.path().filename();
        EXPECT_TRUE(name == "manifest.json" || name == "ids" || name.rfind("epoch-", 0) == 0) << name;
      }
    }
  }
}

// 12,000 particles in two clumps and a background, without a box, as CSV;
// particle `repeat.to` (if any) is given the ID of particle `repeat.from`;
// the `far` particles read last lie 10^12 and more away.
struct Repeat {
  int from = -1, to = -1;
};
// Compact IDs (100, 103, ...) make an ID index of tables; sparse ones,
// scattered over 64 bits, one of sorted pairs.
enum class Ids { kCompact, kSparse };
std::uint64_t ClumpsId(int i, Ids ids = Ids::kCompact) {
  const std::uint64_t n = static_cast<std::uint64_t>(i);
  return ids == Ids::kCompact ? 100 + 3 * n : (n + 1) * 0x9E3779B97F4A7C15ull;
}
void WriteClumpsCsv(const std::string& csv, Repeat repeat = {}, Ids ids = Ids::kCompact, int far = 0) {
  std::mt19937_64 random(5);
  std::normal_distribution<double> clump(0, 0.3);
  std::uniform_real_distribution<double> background(-20, 35);
  std::ofstream out(csv);
  out << "x,y,z,mass,id\n";
  for (int i = 0; i < 12000; ++i) {
    const bool in_clump = i % 3 != 0;
    const double c = in_clump ? (i % 2 ? 4.0 : -7.0) : 0;
    for (int k = 0; k < 3; ++k) {
      const double x = in_clump ? c + clump(random) : background(random);
      out << (i >= 12000 - far ? 1e12 * (12001 - i) + x : x) << ",";
    }
    out << 1 + (i % 5) << "," << ClumpsId(i == repeat.to ? repeat.from : i, ids) << "\n";
  }
}

// octocosm ingest of a CSV file in batches of 500 particles, on `ranks` MPI
// ranks (0: no mpirun).
std::string SpreadCsvCommand(const std::string& csv, const std::string& store, int ranks,
                             const std::string& flags = "") {
  std::string command = ranks > 0 ? std::string(MPIEXEC) + " -n " + std::to_string(ranks) + " " : std::string();
  return command + OCTOCOSM_BINARY + " ingest -q -n 150 --chunk-particles 500 --memory 64M --neighbours 0 " + flags +
         " -o " + store + " " + csv;
}

// Without a periodic box every rank finds the same bounding cube; a CSV
// file, which cannot seek to a batch, is read through by every rank. The
// ID index's buckets (three of pairs, with sparse IDs) fall where one
// process's do.
TEST_F(IngestRanksTest, ASpreadSnapshotWithoutABoxIsTheStoreOneProcessWrites) {
  for (const Ids ids : {Ids::kCompact, Ids::kSparse}) {
    SCOPED_TRACE(ids == Ids::kCompact ? "compact IDs" : "sparse IDs");
    const std::string tag = ids == Ids::kCompact ? "compact" : "sparse";
    const std::string csv = (dir_.path() / ("points-" + tag + ".csv")).string();
    WriteClumpsCsv(csv, {}, ids);
    auto ingest = [&](const std::string& store, int ranks) {
      return Run(SpreadCsvCommand(csv, store, ranks), ranks > 0 ? kMpiEnvironment : "");
    };
    const std::string single = (dir_.path() / ("single-" + tag)).string();
    const ProgramRun one = ingest(single, 0);
    ASSERT_EQ(one.status, 0) << one.Describe();
    const Dataset expected = Dataset::Open(single);
    const std::vector<std::vector<Bytes>> want_ids = IdIndexBlocks(single);
    ASSERT_EQ(want_ids.size(), 1u);
    ASSERT_GE(want_ids[0].size(), ids == Ids::kCompact ? 2u : 4u);  // buckets, the directory (and the leaf table)
    EXPECT_EQ(GetU32(want_ids[0][0].data() + 4), ids == Ids::kCompact ? 3u : 1u) << "bucket version";
    for (int ranks : {2, 3}) {
      SCOPED_TRACE(std::to_string(ranks) + " ranks");
      const std::string store = (dir_.path() / ("spread-" + tag + "-" + std::to_string(ranks))).string();
      const ProgramRun run = ingest(store, ranks);
      ASSERT_EQ(run.status, 0) << run.Describe();
      const Dataset got = Dataset::Open(store);
      EXPECT_EQ(got.store().dataset(), expected.store().dataset());
      EXPECT_TRUE(EpochBlocks(got, 0) == EpochBlocks(expected, 0)) << "the blocks differ";
      EXPECT_TRUE(IdIndexBlocks(store) == want_ids) << "the ID index's blocks differ";
      const ProgramRun verify = Run(std::string(OCTOCOSM_BINARY) + " verify " + store);
      EXPECT_EQ(verify.status, 0) << verify.Describe();
    }
  }
}

// Far outliers dropped (--drop-outliers) or a box clipped (--clip-box) over
// ranks: each rank surveys and counts its share of the batches, and the
// ranks agree on one verdict, the bulk's cube and the counts a single
// process finds; the store is that process's.
TEST_F(IngestRanksTest, OutliersDroppedOrABoxClippedOverRanksGiveTheStoreOneProcessWrites) {
  const std::string csv = (dir_.path() / "far.csv").string();
  WriteClumpsCsv(csv, {}, Ids::kCompact, 3);
  for (const std::string flags : {"--drop-outliers", "--clip-box -10,-10,-10,10,10,10"}) {
    SCOPED_TRACE(flags);
    const std::string single = (dir_.path() / "single").string();
    fs::remove_all(single);
    const ProgramRun one = Run(SpreadCsvCommand(csv, single, 0, flags));
    ASSERT_EQ(one.status, 0) << one.Describe();
    const Dataset expected = Dataset::Open(single);
    ASSERT_LE(expected.store().dataset().at("epochs").at(0).at("points").get<std::uint64_t>(), 12000u - 3);
    for (int ranks : {2, 3}) {
      SCOPED_TRACE(std::to_string(ranks) + " ranks");
      const std::string store = (dir_.path() / ("spread-" + std::to_string(ranks))).string();
      fs::remove_all(store);
      const ProgramRun run = Run(SpreadCsvCommand(csv, store, ranks, flags), kMpiEnvironment);
      ASSERT_EQ(run.status, 0) << run.Describe();
      const Dataset got = Dataset::Open(store);
      EXPECT_EQ(got.store().dataset(), expected.store().dataset());
      EXPECT_TRUE(EpochBlocks(got, 0) == EpochBlocks(expected, 0)) << "the blocks differ";
    }
  }
  // Without a way out, every rank refuses the far particles as one process does.
  const std::string store = (dir_.path() / "refused").string();
  const ProgramRun refused = Run(SpreadCsvCommand(csv, store, 2), kMpiEnvironment);
  EXPECT_NE(refused.status, 0) << refused.Describe();
  EXPECT_NE(refused.output.find("3 particles lie"), std::string::npos) << refused.output;
  EXPECT_NE(refused.output.find("far.csv"), std::string::npos) << refused.output;
  EXPECT_FALSE(fs::exists(store)) << "left behind: " << store;
}

// Two particles with one ID that different ranks read (each rank reads
// every P-th batch of 500), whether they then meet in one rank's domains or
// lie in two ranks' domains, end the ingest as one process's does: an error
// naming the snapshot and the ID, and no store.
TEST_F(IngestRanksTest, AnIdGivenTwiceAcrossRanksIsRefusedNamingTheSnapshot) {
  struct Case {
    int ranks;
    Repeat repeat;
    Ids ids = Ids::kCompact;
  };
  // Particles 11 and 515 lie in the same clump, 10 and 511 in different
  // ones; 1015 is read by the third rank of three.
  const Case cases[] = {{2, {11, 515}},           {2, {10, 511}},           {3, {11, 1015}},
                        {3, {10, 1015}},          {2, {10, 511}, Ids::kSparse}, {3, {11, 1015}, Ids::kSparse}};
  for (const Case& c : cases) {
    SCOPED_TRACE(std::to_string(c.ranks) + " ranks, particle " + std::to_string(c.repeat.to) + " given the ID of " +
                 std::to_string(c.repeat.from) + (c.ids == Ids::kSparse ? ", sparse IDs" : ""));
    const std::string csv = (dir_.path() / "repeated.csv").string();
    WriteClumpsCsv(csv, c.repeat, c.ids);
    const std::string store = (dir_.path() / "store").string();
    const ProgramRun run = Run(SpreadCsvCommand(csv, store, c.ranks), kMpiEnvironment);
    EXPECT_NE(run.status, 0) << run.Describe();
    EXPECT_NE(run.output.find("repeated.csv"), std::string::npos) << run.output;
    EXPECT_NE(run.output.find("ID " + std::to_string(ClumpsId(c.repeat.from, c.ids)) + " is given to more than one particle"),
              std::string::npos)
        << run.output;
    EXPECT_FALSE(fs::exists(store)) << "left behind: " << store;
  }
}

TEST_F(IngestRanksTest, AFailedRankOfASpreadEpochEndsTheIngestAndLeavesNoStore) {
  fs::resize_file(inputs_[0], fs::file_size(inputs_[0]) / 2);
  const std::string store = (dir_.path() / "store").string();
  const ProgramRun run = Run(std::string(MPIEXEC) + " -n 2 " + OCTOCOSM_BINARY + " ingest -q --neighbours 0 -o " +
                                 store + " " + inputs_[0],
                             kMpiEnvironment);
  EXPECT_NE(run.status, 0) << run.Describe();
  EXPECT_NE(run.output.find(fs::path(inputs_[0]).filename().string()), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("ingest rank"), std::string::npos) << run.output;
  EXPECT_FALSE(fs::exists(store)) << "left behind: " << store;
}

TEST_F(IngestRanksTest, AFailedRankEndsTheIngestWithItsErrorAndLeavesNoStore) {
  // The fifth epoch, rank 1's on two ranks, cut short.
  fs::resize_file(inputs_[4], fs::file_size(inputs_[4]) / 2);
  const std::string store = (dir_.path() / "store").string();
  const ProgramRun run = Ingest(store, 2);
  EXPECT_NE(run.status, 0) << run.Describe();
  EXPECT_NE(run.output.find(fs::path(inputs_[4]).filename().string()), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("ingest rank 1"), std::string::npos) << run.output;
  EXPECT_FALSE(fs::exists(store)) << "left behind: " << store;
}

}  // namespace
}  // namespace octocosm
