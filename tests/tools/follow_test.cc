// `octocosm follow` and the query output formats: trajectories read through
// the ID index agree with the snapshots they were ingested from, and the
// writers produce what docs/QUERIES.md says.
#include "tools/cmd_query.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <unistd.h>

#include "base/error.h"
#include "ingest/ingest.h"
#include "ingest/snapshot/snapshot_source.h"
#include "query/particle_lookup.h"
#include "tools/query_output.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

constexpr double kBox = 50.0;
constexpr char kLayout[] = "xyz:f64,vel:f32,mass:f64,id:u64";

class FollowTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocosm-follow-test-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Three epochs of particles drifting through a periodic box; epoch 1 lacks
  // the particles with id % 10 == 3, so follow has something to miss.
  std::vector<std::string> WriteEpochs(std::size_t n) const {
    std::mt19937_64 rng(21);
    std::uniform_real_distribution<double> uniform(0, kBox), kick(-1.0, 1.0);
    std::vector<std::array<double, 3>> x(n);
    for (auto& p : x) p = {uniform(rng), uniform(rng), uniform(rng)};
    std::vector<std::string> files;
    for (int e = 0; e < 3; ++e) {
      const fs::path path = dir_ / ("epoch" + std::to_string(e) + ".raw");
      std::ofstream out(path, std::ios::binary);
      for (std::size_t i = 0; i < n; ++i) {
        for (double& c : x[i]) {
          c += kick(rng);
          c -= kBox * std::floor(c / kBox);
        }
        const std::uint64_t id = 100 + i;
        if (e == 1 && id % 10 == 3) continue;
        const float v[3] = {static_cast<float>(e), static_cast<float>(i % 13), -0.25f * static_cast<float>(i % 4)};
        const double mass = 1;
        out.write(reinterpret_cast<const char*>(x[i].data()), 24);
        out.write(reinterpret_cast<const char*>(v), sizeof v);
        out.write(reinterpret_cast<const char*>(&mass), sizeof mass);
        out.write(reinterpret_cast<const char*>(&id), sizeof id);
      }
      files.push_back(path.string());
    }
    return files;
  }

  std::string Ingested(const std::vector<std::string>& inputs) const {
    IngestOptions o;
    o.inputs = inputs;
    o.output = (dir_ / "store").string();
    o.temp_dir = dir_.string();
    o.quiet = true;
    o.page_size = 4096;
    o.threads = 2;
    o.read.format = "raw";
    o.read.raw = RawLayout::Parse(kLayout);
    o.read.box_size_override = kBox;
    o.tree.capacity = 100;
    Ingest(o);
    return o.output;
  }

  fs::path dir_;
};

struct Truth {
  std::array<double, 3> x;
  std::array<float, 3> v;
};

std::map<std::uint64_t, Truth> ReadSnapshot(const std::string& path) {
  ReadOptions options;
  options.format = "raw";
  options.raw = RawLayout::Parse(kLayout);
  auto source = OpenSnapshot(path, options);
  std::map<std::uint64_t, Truth> truth;
  ParticleChunk chunk;
  while (source->Next(chunk)) {
    for (std::size_t i = 0; i < chunk.id.size(); ++i) {
      truth[chunk.id[i]] = {{chunk.position[3 * i], chunk.position[3 * i + 1], chunk.position[3 * i + 2]},
                            {chunk.velocity[3 * i], chunk.velocity[3 * i + 1], chunk.velocity[3 * i + 2]}};
    }
  }
  return truth;
}

TEST_F(FollowTest, TrajectoriesMatchTheSnapshotsWithinTheQuantizationBound) {
  const auto inputs = WriteEpochs(3000);
  const Dataset dataset = Dataset::Open(Ingested(inputs));
  ASSERT_EQ(dataset.epoch_count(), 3u);
  std::vector<std::map<std::uint64_t, Truth>> truth;
  for (const auto& input : inputs) truth.push_back(ReadSnapshot(input));

  std::vector<std::uint64_t> ids;
  for (std::uint64_t id = 100; id < 3100; id += 7) ids.push_back(id);
  ids.push_back(999999);  // in no epoch
  std::ostringstream csv, notes;
  const FollowReport report = WriteTrajectories(dataset, ids, csv, notes);

  std::istringstream lines(csv.str());
  std::string line;
  std::getline(lines, line);
  EXPECT_EQ(line, "id,epoch,time,x,y,z,vx,vy,vz");
  std::size_t rows = 0;
  std::map<std::uint64_t, int> epochs_seen;
  while (std::getline(lines, line)) {
    std::uint64_t id;
    unsigned epoch;
    double time, x[3], v[3];
    ASSERT_EQ(std::sscanf(line.c_str(), "%lu,%u,%lf,%lf,%lf,%lf,%lf,%lf,%lf", &id, &epoch, &time, &x[0], &x[1], &x[2],
                          &v[0], &v[1], &v[2]),
              9)
        << line;
    ASSERT_LT(epoch, 3u);
    const auto it = truth[epoch].find(id);
    ASSERT_NE(it, truth[epoch].end()) << "particle " << id << " is not in epoch " << epoch << " of the input";
    // The leaf is unknown here, so bound by the ID index's leaf for this particle.
    ParticleLocator locator(dataset);
    const auto state = locator.FindInEpoch(epoch, std::span<const std::uint64_t>(&id, 1), false)[0];
    ASSERT_TRUE(state.has_value());
    const double bound = dataset.cube(epoch).NodeSize(state->leaf.level()) / 131072.0 * (1 + 1e-9);
    for (int a = 0; a < 3; ++a) {
      EXPECT_LE(std::fabs(x[a] - it->second.x[a]), bound) << "particle " << id << " epoch " << epoch;
      // Velocities are quantized to 16 bits over the block's range (a few units here).
      EXPECT_NEAR(v[a], it->second.v[a], 1e-3) << "particle " << id << " epoch " << epoch;
    }
    ++epochs_seen[id];
    ++rows;
  }
  EXPECT_EQ(rows, report.rows);
  std::size_t expected_missing = 3;  // 999999 in every epoch
  for (std::uint64_t id : ids) {
    if (id == 999999) continue;
    const int expected = id % 10 == 3 ? 2 : 3;
    EXPECT_EQ(epochs_seen[id], expected) << id;
    expected_missing += 3 - static_cast<std::size_t>(expected);
  }
  EXPECT_EQ(report.missing, expected_missing);
  EXPECT_NE(notes.str().find("particle 999999 is not in epoch 0"), std::string::npos) << notes.str();
  EXPECT_NE(notes.str().find("particle 163 is not in epoch 1"), std::string::npos) << notes.str();
}

TEST_F(FollowTest, IdFileAllowsCommentsAndNamesTheBadLine) {
  const fs::path good = dir_ / "ids.txt";
  std::ofstream(good) << "# particles of interest\n12\n\n  7  # a comment\r\n18446744073709551615\n";
  EXPECT_EQ(ReadIdFile(good.string()), (std::vector<std::uint64_t>{12, 7, 18446744073709551615ull}));
  const fs::path bad = dir_ / "bad.txt";
  std::ofstream(bad) << "1\n2\nthree\n";
  try {
    ReadIdFile(bad.string());
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    EXPECT_NE(std::string(e.what()).find("line 3"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("bad.txt"), std::string::npos) << e.what();
  }
  std::ofstream(bad) << "-4\n";
  EXPECT_THROW(ReadIdFile(bad.string()), Error);
  EXPECT_THROW(ReadIdFile((dir_ / "absent.txt").string()), Error);
}

QueryBatch TwoPoints() {
  QueryBatch batch;
  batch.count = 2;
  batch.points.position = {1.5, 2.5, 3.5, -4, 5, 6.25};
  batch.points.weight = {0.5, 2};
  batch.points.id = {42, 1ull << 40};
  batch.points.velocity = {1, 2, 3, 4, 5, 6};
  return batch;
}

TEST(QueryOutputTest, CsvBinaryAndPlyHoldTheColumnsAsked) {
  const ColumnSet columns = ParseColumnList("weight,id");
  std::ostringstream csv;
  auto writer = MakePointWriter(PointFormat::kCsv, columns, csv);
  writer->Write(TwoPoints());
  writer->Finish();
  EXPECT_EQ(csv.str(), "x,y,z,weight,id\n1.5,2.5,3.5,0.5,42\n-4,5,6.25,2,1099511627776\n");

  std::ostringstream bin;
  writer = MakePointWriter(PointFormat::kBinary, columns, bin);
  writer->Write(TwoPoints());
  writer->Finish();
  const std::string bytes = bin.str();
  ASSERT_EQ(BinaryRecordSize(columns), 40u);
  ASSERT_EQ(bytes.size(), 16 + 2 * 40u);
  EXPECT_EQ(bytes.substr(0, 4), "OCQ1");
  double x;
  std::uint64_t id;
  std::memcpy(&x, bytes.data() + 16 + 40, 8);
  std::memcpy(&id, bytes.data() + 16 + 40 + 32, 8);
  EXPECT_EQ(x, -4);
  EXPECT_EQ(id, 1ull << 40);

  std::ostringstream ply;
  writer = MakePointWriter(PointFormat::kPly, ParseColumnList("velocity"), ply);
  writer->Write(TwoPoints());
  writer->Finish();
  const std::string text = ply.str();
  const std::string header_end = "end_header\n";
  const std::size_t body = text.find(header_end);
  ASSERT_NE(body, std::string::npos);
  const std::string header = text.substr(0, body);
  EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos);
  EXPECT_NE(header.find("element vertex 2\n"), std::string::npos);
  EXPECT_NE(header.find("property double x\n"), std::string::npos);
  EXPECT_NE(header.find("property float vz\n"), std::string::npos);
  EXPECT_EQ(text.size() - body - header_end.size(), 2 * (24 + 12u));

  EXPECT_THROW(ParseColumnList("weight,colour"), Error);
  EXPECT_THROW(ParsePointFormat("xml"), Error);
}

TEST(QueryOutputTest, EpochLinkColumnsHaveTheirOwnFieldsInBlockOrder) {
  QueryBatch batch = TwoPoints();
  batch.points.type = {3, 250};
  batch.points.displacement = {0.5f, 0, 0, 0, 0, -0.5f};
  batch.points.next_velocity = {7, 8, 9, 10, 11, 12};
  batch.points.prev_displacement = {-0.5f, 0, 0, 0, 0, 0.5f};
  // prev_velocity left empty: a store without it gives zeros.
  const ColumnSet columns = ParseColumnList("prev_velocity,next_velocity,type,prev_displacement,displacement");
  std::ostringstream csv;
  auto writer = MakePointWriter(PointFormat::kCsv, columns, csv);
  writer->Write(batch);
  writer->Finish();
  EXPECT_EQ(csv.str(),
            "x,y,z,type,dx,dy,dz,nvx,nvy,nvz,pdx,pdy,pdz,pvx,pvy,pvz\n"
            "1.5,2.5,3.5,3,0.5,0,0,7,8,9,-0.5,0,0,0,0,0\n"
            "-4,5,6.25,250,0,0,-0.5,10,11,12,0,0,0.5,0,0,0\n");

  std::ostringstream bin;
  writer = MakePointWriter(PointFormat::kBinary, columns, bin);
  writer->Write(batch);
  writer->Finish();
  const std::size_t record = 24 + 1 + 4 * 12;
  ASSERT_EQ(BinaryRecordSize(columns), record);
  const std::string bytes = bin.str();
  ASSERT_EQ(bytes.size(), 16 + 2 * record);
  std::uint32_t bits;
  std::memcpy(&bits, bytes.data() + 4, 4);
  EXPECT_EQ(bits, (1u << 1) | (1u << 6) | (1u << 7) | (1u << 8) | (1u << 9) | (1u << 10));
  float next_vz, prev_dz;
  std::memcpy(&next_vz, bytes.data() + 16 + record + 25 + 12 + 8, 4);
  std::memcpy(&prev_dz, bytes.data() + 16 + record + 25 + 24 + 8, 4);
  EXPECT_EQ(next_vz, 12);
  EXPECT_EQ(prev_dz, 0.5f);

  std::ostringstream ply;
  writer = MakePointWriter(PointFormat::kPly, columns, ply);
  writer->Write(batch);
  writer->Finish();
  for (const char* property : {"property float nvx\n", "property float pdy\n", "property float pvz\n"}) {
    EXPECT_NE(ply.str().find(property), std::string::npos) << property;
  }
}

// The clusters' velocity dispersion is one float field after the vector
// columns; a batch of a leaf, which carries none, gives 0.
TEST(QueryOutputTest, VelocityDispersionIsOneFloatFieldLast) {
  QueryBatch cluster = TwoPoints();
  cluster.points.velocity_dispersion = {2.5f, 0.125f};
  const QueryBatch leaf = TwoPoints();
  const ColumnSet columns = ParseColumnList("velocity_dispersion,velocity");
  EXPECT_EQ(ParseColumnList("all") & ColumnBit(ColumnId::kVelocityDispersion), ColumnBit(ColumnId::kVelocityDispersion));
  std::ostringstream csv;
  auto writer = MakePointWriter(PointFormat::kCsv, columns, csv);
  writer->Write(cluster);
  writer->Write(leaf);
  writer->Finish();
  EXPECT_EQ(csv.str(),
            "x,y,z,vx,vy,vz,velocity_dispersion\n"
            "1.5,2.5,3.5,1,2,3,2.5\n"
            "-4,5,6.25,4,5,6,0.125\n"
            "1.5,2.5,3.5,1,2,3,0\n"
            "-4,5,6.25,4,5,6,0\n");

  std::ostringstream bin;
  writer = MakePointWriter(PointFormat::kBinary, columns, bin);
  writer->Write(cluster);
  writer->Finish();
  const std::size_t record = 24 + 12 + 4;
  ASSERT_EQ(BinaryRecordSize(columns), record);
  const std::string bytes = bin.str();
  ASSERT_EQ(bytes.size(), 16 + 2 * record);
  std::uint32_t bits;
  std::memcpy(&bits, bytes.data() + 4, 4);
  EXPECT_EQ(bits, (1u << 1) | (1u << 4) | (1u << 11));
  float sigma;
  std::memcpy(&sigma, bytes.data() + 16 + record + 36, 4);
  EXPECT_EQ(sigma, 0.125f);

  std::ostringstream ply;
  writer = MakePointWriter(PointFormat::kPly, columns, ply);
  writer->Write(cluster);
  writer->Finish();
  EXPECT_NE(ply.str().find("property float vz\nproperty float velocity_dispersion\n"), std::string::npos) << ply.str();
}

}  // namespace
}  // namespace octocosm
