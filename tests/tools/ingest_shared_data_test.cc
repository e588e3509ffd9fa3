// octocosm ingest on the real snapshots in ../shared/data (ctest label
// shared-data; skipped when the folder is absent).
#include <gtest/gtest.h>


#include <cstdio>
#include <filesystem>
#include <map>
#include <unordered_map>

#include "index/dataset.h"
#include "tests/tools/ingest_fixture.h"
#include "tests/tools/store_check.h"
#include "tools/ingest/ingest.h"
#include "tools/snapshot/snapshot_source.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using namespace testing_support;

class SharedDataIngestTest : public IngestFixture {
 protected:
  static constexpr const char* kData = OCTOCOSM_SHARED_DATA;
  void SetUp() override {
    if (!fs::is_directory(kData)) GTEST_SKIP() << "no shared data folder at " << kData;
  }
};

TEST_F(SharedDataIngestTest, GadgetFilesIngestWithTheirCountsTypesAndIds) {
  struct Case {
    std::string path;
    std::map<int, std::uint64_t> types;
    std::uint64_t first_id, last_id;
  };
  const std::string d = kData;
  const std::vector<Case> cases = {
      {d + "/gadget2_ics/lcdm_gas_littleendian.dat", {{0, 32768}, {1, 32768}}, 1, 65536},
      {d + "/gadget2_ics/lcdm_gas_bigendian.dat", {{0, 32768}, {1, 32768}}, 1, 65536},
      {d + "/gadget2_ics/galaxy_littleendian.dat", {{1, 40000}, {2, 20000}}, 1, 60000},
      {d + "/gadget2_ics/gassphere_littleendian.dat", {{0, 1472}}, 1, 1472},
      {d + "/gadget2_format2_multifile/test_g2_snap", {{0, 4039}, {1, 4096}, {4, 57}}, 1, 8192},
  };
  std::map<std::uint64_t, std::vector<Bytes>> lcdm_blocks;
  for (std::size_t c = 0; c < cases.size(); ++c) {
    IngestOptions o = Options({cases[c].path}, "store" + std::to_string(c));
    o.tree.capacity = 4000;
    if (cases[c].path.find("lcdm") != std::string::npos) o.read.box_size_override = 50000;
    Ingest(o);
    const Dataset dataset = Dataset::Open(o.output);
    const TreeCheck check = CheckTree(dataset, 0);
    EXPECT_EQ(TypeCounts(check), cases[c].types) << cases[c].path;
    std::uint64_t expected = 0;
    for (const auto& [t, n] : cases[c].types) expected += n;
    ASSERT_EQ(check.leaf_points.size(), expected) << cases[c].path;
    for (std::uint64_t id = cases[c].first_id; id <= cases[c].last_id; ++id) {
      ASSERT_TRUE(check.leaf_points.count(id)) << cases[c].path << " lost ID " << id;
    }
    if (c < 2) {
      if (c == 0) lcdm_blocks = check.blocks;
      else EXPECT_TRUE(check.blocks == lcdm_blocks) << "big and little endian files must give identical stores";
    }
  }
  EXPECT_TRUE(TempIsEmpty());
}

TEST_F(SharedDataIngestTest, Hdf5TimeSeriesDisplacementsMatchTheNextEpoch) {
  std::vector<std::string> inputs;
  for (int i = 0; i <= 20; ++i) {
    char name[64];
    std::snprintf(name, sizeof name, "/gadget4_hdf5_galaxy_collision_timeseries/snapshot_%03d.hdf5", i);
    inputs.push_back(std::string(kData) + name);
  }
  IngestOptions o = Options(inputs, "series");
  o.tree.capacity = 5000;
  o.page_size = 65536;
  Ingest(o);
  const Dataset dataset = Dataset::Open(o.output);
  ASSERT_EQ(dataset.epoch_count(), 21u);
  std::unordered_map<std::uint64_t, std::array<double, 3>> next_positions;
  for (int e = 20; e >= 0; --e) {
    const TreeCheck check = CheckTree(dataset, static_cast<std::uint32_t>(e));
    ASSERT_EQ(check.leaf_points.size(), 60000u);
    EXPECT_EQ(TypeCounts(check), (std::map<int, std::uint64_t>{{1, 40000}, {2, 20000}}));
    // Read the true positions of this epoch straight from the file.
    std::unordered_map<std::uint64_t, std::array<double, 3>> positions;
    auto source = OpenSnapshot(inputs[static_cast<std::size_t>(e)], {});
    ParticleChunk chunk;
    while (source->Next(chunk)) {
      for (std::size_t i = 0; i < chunk.size(); ++i) {
        positions[chunk.id[i]] = {chunk.position[3 * i], chunk.position[3 * i + 1], chunk.position[3 * i + 2]};
      }
    }
    if (e < 20) {
      double worst = 0;
      for (const auto& [id, lp] : check.leaf_points) {
        ASSERT_TRUE(lp.Has(VectorColumn::kDisplacement));
        for (int a = 0; a < 3; ++a) {
          const double truth = next_positions.at(id)[a] - positions.at(id)[a];
          worst = std::max(worst, std::fabs(lp.Vector(VectorColumn::kDisplacement)[a] - truth) / std::max(1.0, std::fabs(truth)));
        }
      }
      // Per-block quantization of the displacement (16 bits over the block's range) and float32.
      EXPECT_LT(worst, 2e-3) << "epoch " << e;
    }
    next_positions = std::move(positions);
  }
}

}  // namespace
}  // namespace octocosm
