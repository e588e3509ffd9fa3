// Outliers at ingest: far particles that would cost the bulk its precision
// are refused naming the file, unless dropped (--drop-outliers) or clipped
// away (--clip-box), and every count after a drop tells read from stored.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "index/dataset.h"
#include "ingest/clipped_source.h"
#include "ingest/ingest.h"
#include "ingest/outliers.h"
#include "index/store_verify.h"
#include "tests/ingest/ingest_fixture.h"
#include "tests/ingest/store_check.h"
#include "tests/support/thread_rank_group.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using namespace testing_support;

// Clustered points in [origin, origin + size)^3.
std::vector<Particle> Clustered(std::size_t n, std::uint64_t seed, double origin, double size) {
  ClusteredSpec spec;
  spec.origin = origin;
  spec.size = size;
  spec.halos = 5;
  spec.mass_cycle = 5;
  spec.first_id = 7;
  spec.id_step = 1;
  return testing_support::Clustered(n, seed, spec);
}

PositionSurvey Survey(const std::vector<Particle>& particles) {
  ParticleChunk chunk;
  for (const Particle& p : particles) {
    chunk.position.insert(chunk.position.end(), p.x, p.x + 3);
    chunk.mass.push_back(p.mass);
    chunk.type.push_back(0);
  }
  PositionSurvey survey;
  survey.Add(chunk, 0);
  return survey;
}


// The "dropped" entries the manifest records in the epoch's input.
nlohmann::json DroppedInManifest(const std::string& store, std::size_t epoch) {
  std::ifstream in(fs::path(store) / "manifest.json");
  const nlohmann::json manifest = nlohmann::json::parse(in);
  return manifest.at("dataset").at("epochs").at(epoch).at("input").at("extra").value("dropped", nlohmann::json());
}

class IngestOutlierTest : public IngestFixture {
 protected:
  IngestOptions RawOptions(std::vector<std::string> inputs, const std::string& out) const {
    IngestOptions o = Options(std::move(inputs), out);
    o.read.format = "raw";
    o.read.raw = RawLayout::Parse("xyz:f64,mass:f64,id:u64");
    o.tree.capacity = 1000;
    o.neighbours = 0;
    return o;
  }
};

// 65,535 particles with coordinates about 10^4 and one at 3 x 10^38.
std::vector<Particle> BulkWithOneFarOutlier() {
  auto particles = Clustered(65536, 1, 1e4, 1e4);
  particles[40000].x[0] = 3e38;
  return particles;
}

TEST(OutlierRule, FlagsAFarOutlierButNotOrdinaryOrModeratelyFarData) {
  const OutlierVerdict far = JudgeOutliers(Survey(BulkWithOneFarOutlier()));
  EXPECT_TRUE(far.outliers);
  EXPECT_LT(far.bulk.LargestExtent(), 4e4);
  EXPECT_GT(far.spacing, 100);

  EXPECT_FALSE(JudgeOutliers(Survey(Clustered(50000, 2, -3e3, 1e3))).outliers);
  // A laser-scan-like set: a flat scan of 100 units with a few points 10^5 away.
  auto scan = Clustered(50000, 3, 0, 100);
  for (Particle& p : scan) p.x[2] = 0.01 * p.x[2];
  for (int k = 0; k < 5; ++k) scan[k * 1000].x[k % 3] = k % 2 ? 1e5 : -1e5;
  const OutlierVerdict moderate = JudgeOutliers(Survey(scan));
  EXPECT_FALSE(moderate.outliers) << moderate.spacing << " " << moderate.finest_cell;
  // Every particle at one point: nothing to lose.
  std::vector<Particle> coincident(100, Particle{{5, 5, 5}, 1, 0});
  coincident[3].x[1] = 1e300;
  EXPECT_FALSE(JudgeOutliers(Survey(coincident)).outliers);
}

// One batch per call from memory, every column filled.
class BatchSource : public ParticleSource {
 public:
  explicit BatchSource(std::vector<ParticleChunk> batches) : batches_(std::move(batches)) {
    header_.files = {"memory"};
    header_.count_per_type = {0, 0};
    for (const ParticleChunk& b : batches_) {
      for (std::uint8_t t : b.type) ++header_.count_per_type[t];
      header_.total_count += b.size();
    }
    header_.has_id = header_.has_velocity = header_.has_smoothing = true;
  }
  const SnapshotHeader& header() const override { return header_; }
  bool Next(ParticleChunk& chunk) override {
    if (next_ == batches_.size()) {
      chunk.clear();
      return false;
    }
    chunk = batches_[next_++];
    ++reads_;
    return true;
  }
  std::uint64_t Skip() override { return next_ == batches_.size() ? 0 : batches_[next_++].size(); }
  void Rewind() override { next_ = 0; }
  // Batches handed out by Next (not skipped).
  std::size_t reads() const { return reads_; }

 private:
  std::vector<ParticleChunk> batches_;
  SnapshotHeader header_;
  std::size_t next_ = 0;
  std::size_t reads_ = 0;
};

// 13 batches of 6,000 to 8,400 particles (more than a survey samples), with
// masses whose sums are exact in any order.
std::vector<ParticleChunk> ManyBatches() {
  std::mt19937_64 random(11);
  std::normal_distribution<double> bulk(0, 10);
  std::vector<ParticleChunk> batches(13);
  for (std::size_t b = 0; b < batches.size(); ++b) {
    for (std::size_t i = 0; i < 6000 + 200 * b; ++i) {
      const bool far = i == 17 && b % 4 == 1;
      for (int a = 0; a < 3; ++a) batches[b].position.push_back(far ? 1e9 * static_cast<double>(b) : bulk(random));
      batches[b].mass.push_back(static_cast<double>(1 + i % 3));
      batches[b].id.push_back(b * 100000 + i);
      batches[b].type.push_back(static_cast<std::uint8_t>(i % 2));
      batches[b].smoothing.push_back(1);
      batches[b].velocity.insert(batches[b].velocity.end(), {0, 0, 0});
    }
  }
  return batches;
}

TEST(PositionSurvey, SurveysOfSharesMergedAreTheSurveyOfTheWholeInAnyOrder) {
  const std::vector<ParticleChunk> batches = ManyBatches();
  BatchSource whole_source(batches);
  const PositionSurvey whole = SurveyPositions(whole_source, "survey");
  ASSERT_GT(whole.bounds().count, kSurveySamplePoints);
  const Bytes want = whole.Encode();
  EXPECT_EQ(PositionSurvey::Decode(want).Encode(), want);
  // Two halves, merged either way round.
  std::uint64_t index = 0;
  PositionSurvey first, second;
  for (std::size_t b = 0; b < batches.size(); ++b) {
    (b < 5 ? first : second).Add(batches[b], index);
    index += batches[b].size();
  }
  PositionSurvey first_then_second = first, second_then_first = second;
  first_then_second.Merge(second);
  second_then_first.Merge(first);
  EXPECT_EQ(first_then_second.Encode(), want);
  EXPECT_EQ(second_then_first.Encode(), want);
  // Ranks that each read their share of the batches, and skip the others.
  for (const int ranks : {2, 3, 5}) {
    SCOPED_TRACE(std::to_string(ranks) + " ranks");
    std::vector<Bytes> got(static_cast<std::size_t>(ranks));
    std::vector<std::size_t> reads(static_cast<std::size_t>(ranks));
    testing_support::RunRanks(ranks, [&](RankGroup& group) {
      BatchSource share(batches);
      got[static_cast<std::size_t>(group.rank())] = SurveyPositions(share, "survey", &group).Encode();
      reads[static_cast<std::size_t>(group.rank())] = share.reads();
    });
    for (int r = 0; r < ranks; ++r) {
      EXPECT_EQ(got[static_cast<std::size_t>(r)], want) << "rank " << r;
      EXPECT_EQ(reads[static_cast<std::size_t>(r)], (batches.size() - static_cast<std::size_t>(r) + ranks - 1) / ranks)
          << "rank " << r << " read batches beyond its share";
    }
  }
}

TEST(ClippedSource, RanksCountingSharesHoldTheCountsOfTheWhole) {
  const std::vector<ParticleChunk> batches = ManyBatches();
  const PositionBox box{{-100, -100, -100}, {100, 100, 100}};  // drops the far particles
  const ClippedSource whole(std::make_unique<BatchSource>(batches), box, "test");
  ASSERT_EQ(whole.dropped(), 3u);
  ASSERT_GT(whole.farthest_dropped(), 1e9);
  for (const int ranks : {2, 3}) {
    SCOPED_TRACE(std::to_string(ranks) + " ranks");
    testing_support::RunRanks(ranks, [&](RankGroup& group) {
      auto share = std::make_unique<BatchSource>(batches);
      const BatchSource* counted = share.get();
      const ClippedSource clipped(std::move(share), box, "test", &group);
      EXPECT_LT(counted->reads(), batches.size());
      EXPECT_EQ(clipped.dropped(), whole.dropped());
      EXPECT_EQ(clipped.farthest_dropped(), whole.farthest_dropped());
      EXPECT_EQ(clipped.header().total_count, whole.header().total_count);
      EXPECT_EQ(clipped.header().count_per_type, whole.header().count_per_type);
      EXPECT_EQ(clipped.header().extra, whole.header().extra);
      EXPECT_EQ(clipped.survey().Encode(), whole.survey().Encode());
    });
  }
}

TEST(ClippedSource, KeepsEveryColumnOfTheParticlesInsideAndCountsTheRest) {
  std::vector<ParticleChunk> batches(3);
  for (std::size_t b = 0; b < batches.size(); ++b) {
    for (std::uint64_t i = 0; i < 10; ++i) {
      const std::uint64_t id = b * 10 + i;
      const double x = static_cast<double>(id);
      batches[b].position.insert(batches[b].position.end(), {x, -x, 0.5});
      batches[b].mass.push_back(x + 1);
      batches[b].id.push_back(id);
      batches[b].type.push_back(static_cast<std::uint8_t>(id % 2));
      batches[b].smoothing.push_back(static_cast<float>(x) / 4);
      batches[b].velocity.insert(batches[b].velocity.end(), {static_cast<float>(x), 1, 2});
    }
  }
  // Keeps IDs 5..14 (bounds included), none of the last batch.
  ClippedSource clipped(std::make_unique<BatchSource>(batches), PositionBox{{5, -14, 0}, {14, 0, 1}}, "test");
  EXPECT_EQ(clipped.dropped(), 20u);
  EXPECT_EQ(clipped.farthest_dropped(), 15);  // ID 29 lies 15 beyond x = 14
  EXPECT_EQ(clipped.header().total_count, 10u);
  EXPECT_EQ(clipped.header().count_per_type, (std::vector<std::uint64_t>{5, 5}));
  EXPECT_EQ(clipped.survey().bounds().count, 10u);
  const nlohmann::json& dropped = clipped.header().extra.at("dropped");
  EXPECT_EQ(dropped.at(0).at("read"), 30);
  EXPECT_EQ(dropped.at(0).at("dropped"), 20);
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<std::uint64_t> ids;
    ParticleChunk chunk;
    while (clipped.Next(chunk)) {
      ASSERT_GT(chunk.size(), 0u);
      for (std::size_t i = 0; i < chunk.size(); ++i) {
        const double x = static_cast<double>(chunk.id[i]);
        EXPECT_EQ(chunk.position[3 * i], x);
        EXPECT_EQ(chunk.position[3 * i + 1], -x);
        EXPECT_EQ(chunk.mass[i], x + 1);
        EXPECT_EQ(chunk.type[i], chunk.id[i] % 2);
        EXPECT_EQ(chunk.smoothing[i], static_cast<float>(x) / 4);
        EXPECT_EQ(chunk.velocity[3 * i], static_cast<float>(x));
        EXPECT_EQ(chunk.velocity[3 * i + 2], 2.0f);
        ids.push_back(chunk.id[i]);
      }
    }
    EXPECT_EQ(ids, (std::vector<std::uint64_t>{5, 6, 7, 8, 9, 10, 11, 12, 13, 14}));
    clipped.Rewind();
  }
  EXPECT_EQ(clipped.dropped(), 20u);  // counted once, whatever the passes
}

TEST_F(IngestOutlierTest, AFarOutlierIsRefusedNamingTheFileTheCountAndTheWaysOut) {
  const std::string input = WriteRaw(dir_ / "far.raw", BulkWithOneFarOutlier());
  IngestOptions o = RawOptions({input}, "store");
  ExpectBadInputFrom([&] { Ingest(o); }, {input + ": 1 particle lies far outside the bulk", "up to 3e+38 beyond it",
                                          "--drop-outliers", "--clip-box", "--cube"});
  EXPECT_FALSE(fs::exists(o.output));
  EXPECT_TRUE(TempIsEmpty());
}

TEST_F(IngestOutlierTest, DropOutliersKeepsTheBulkAtFullPrecisionAndCountsTheDrop) {
  const auto particles = BulkWithOneFarOutlier();
  IngestOptions o = RawOptions({WriteRaw(dir_ / "far.raw", particles)}, "store");
  o.drop_outliers = true;
  o.neighbours = 8;  // the neighbour pass reads the kept particles only
  const IngestReport report = Ingest(o);
  ASSERT_EQ(report.epochs.size(), 1u);
  EXPECT_EQ(report.epochs[0].read_points, particles.size());
  EXPECT_EQ(report.epochs[0].dropped_points, 1u);
  EXPECT_EQ(report.epochs[0].points, particles.size() - 1);
  EXPECT_EQ(report.dropped_points, 1u);
  EXPECT_EQ(report.input_points, particles.size() - 1);
  EXPECT_TRUE(TempIsEmpty());

  const Dataset dataset = Dataset::Open(o.output);
  const Cube& cube = dataset.cube(0);
  EXPECT_LT(cube.size, 1.01e4);  // the bulk's bounding cube
  const TreeCheck check = CheckTree(dataset, 0);
  ASSERT_EQ(check.leaf_points.size(), particles.size() - 1);
  std::set<std::array<double, 3>> inputs, stored;
  double mass = 0;
  for (const Particle& p : particles) {
    if (p.x[0] > 1e30) {
      EXPECT_FALSE(check.leaf_points.contains(p.id));
      continue;
    }
    mass += p.mass;
    const auto it = check.leaf_points.find(p.id);
    ASSERT_NE(it, check.leaf_points.end()) << "ID " << p.id;
    const double quantum = cube.NodeSize(it->second.leaf.level()) / 131072.0 * (1 + 1e-9);
    for (int a = 0; a < 3; ++a) ASSERT_LE(std::fabs(it->second.x[a] - p.x[a]), quantum) << "ID " << p.id;
    inputs.insert({p.x[0], p.x[1], p.x[2]});
    stored.insert({it->second.x[0], it->second.x[1], it->second.x[2]});
  }
  EXPECT_EQ(stored.size(), inputs.size());  // distinct particles stay distinct
  EXPECT_NEAR(report.epochs[0].mass, mass, 1e-12 * mass);
  EXPECT_TRUE(VerifyStore(o.output).faults.empty());
  const nlohmann::json dropped = DroppedInManifest(o.output, 0);
  ASSERT_TRUE(dropped.is_array());
  ASSERT_EQ(dropped.size(), 1u);
  EXPECT_EQ(dropped[0].at("reason"), "--drop-outliers");
  EXPECT_EQ(dropped[0].at("read"), particles.size());
  EXPECT_EQ(dropped[0].at("dropped"), 1);
  EXPECT_EQ(dropped[0].at("kept"), particles.size() - 1);
}

TEST_F(IngestOutlierTest, ClipBoxDropsExactlyTheParticlesOutside) {
  const auto particles = Clustered(20000, 4, 0, 100);
  IngestOptions o = RawOptions({WriteRaw(dir_ / "in.raw", particles)}, "store");
  const PositionBox box{{20, 20, 20}, {70, 80, 90}};
  o.clip_box = box;
  const IngestReport report = Ingest(o);
  std::set<std::uint64_t> inside;
  double mass = 0;
  for (const Particle& p : particles) {
    if (p.x[0] >= 20 && p.x[0] <= 70 && p.x[1] >= 20 && p.x[1] <= 80 && p.x[2] >= 20 && p.x[2] <= 90) {
      inside.insert(p.id);
      mass += p.mass;
    }
  }
  ASSERT_GT(inside.size(), 1000u);
  EXPECT_EQ(report.epochs[0].read_points, particles.size());
  EXPECT_EQ(report.epochs[0].dropped_points, particles.size() - inside.size());
  EXPECT_EQ(report.epochs[0].points, inside.size());
  EXPECT_NEAR(report.epochs[0].mass, mass, 1e-12 * mass);
  const TreeCheck check = CheckTree(Dataset::Open(o.output), 0);
  std::set<std::uint64_t> stored;
  for (const auto& [id, point] : check.leaf_points) stored.insert(id);
  EXPECT_EQ(stored, inside);
  EXPECT_TRUE(VerifyStore(o.output).faults.empty());
  const nlohmann::json dropped = DroppedInManifest(o.output, 0);
  ASSERT_EQ(dropped.size(), 1u);
  EXPECT_EQ(dropped[0].at("reason"), "--clip-box");
  EXPECT_EQ(dropped[0].at("dropped"), particles.size() - inside.size());

  IngestOptions empty = RawOptions(o.inputs, "empty");
  empty.clip_box = PositionBox{{200, 200, 200}, {300, 300, 300}};
  ExpectBadInputFrom([&] { Ingest(empty); }, {o.inputs[0], "none of its 20000 particles lies inside the box"});
  EXPECT_FALSE(fs::exists(empty.output));
  IngestOptions inverted = RawOptions(o.inputs, "inverted");
  inverted.clip_box = PositionBox{{20, 20, 20}, {10, 80, 90}};
  EXPECT_THROW(Ingest(inverted), Error);
}

TEST_F(IngestOutlierTest, OrdinaryDataAndAFewModeratelyFarPointsAreTakenWhole) {
  auto particles = Clustered(20000, 5, 0, 100);
  for (int k = 0; k < 4; ++k) particles[k * 3000].x[k % 3] = k % 2 ? 1e5 : -1e5;
  for (const bool drop : {false, true}) {
    IngestOptions o = RawOptions({WriteRaw(dir_ / "far.raw", particles)}, drop ? "dropping" : "store");
    o.drop_outliers = drop;  // finds nothing to drop: the bulk keeps its precision
    const IngestReport report = Ingest(o);
    EXPECT_EQ(report.epochs[0].points, particles.size());
    EXPECT_EQ(report.epochs[0].dropped_points, 0u);
    EXPECT_TRUE(DroppedInManifest(o.output, 0).is_null());
  }
}

// A series: the clip box applies to every epoch, and a particle is dropped
// from the epochs where it lies outside; the epochs where it is kept link it
// as to an epoch that lacks its ID (zeros, counted as missing).
TEST_F(IngestOutlierTest, ClipBoxDropsPerEpochInASeries) {
  const auto first = Clustered(6000, 6, 0, 100);
  auto second = first;
  std::set<std::uint64_t> kept_first, kept_second;
  for (std::size_t i = 0; i < first.size(); ++i) {
    second[i].x[1] += 0.5;
    if (i % 10 == 0) second[i].x[0] = 150;  // leaves the box
    if (i % 10 != 0) kept_second.insert(first[i].id);
  }
  auto shifted_first = first;
  for (std::size_t i = 0; i < first.size(); ++i) {
    if (i % 10 == 1) shifted_first[i].x[2] = -40;  // outside in the first epoch only
    if (i % 10 != 1) kept_first.insert(first[i].id);
  }
  IngestOptions o = RawOptions({WriteRaw(dir_ / "e0.raw", shifted_first), WriteRaw(dir_ / "e1.raw", second)}, "series");
  o.clip_box = PositionBox{{-1, -1, -1}, {120, 120, 120}};
  const IngestReport report = Ingest(o);
  ASSERT_EQ(report.epochs.size(), 2u);
  EXPECT_EQ(report.epochs[0].dropped_points, first.size() - kept_first.size());
  EXPECT_EQ(report.epochs[1].dropped_points, first.size() - kept_second.size());
  EXPECT_EQ(report.epochs[0].missing_in_next, 600u);  // kept in the first, dropped from the second
  EXPECT_EQ(report.epochs[1].missing_in_prev, 600u);
  const Dataset dataset = Dataset::Open(o.output);
  for (std::uint32_t e = 0; e < 2; ++e) {
    std::set<std::uint64_t> stored;
    for (const auto& [id, point] : CheckTree(dataset, e).leaf_points) stored.insert(id);
    EXPECT_EQ(stored, e == 0 ? kept_first : kept_second) << "epoch " << e;
  }
  EXPECT_TRUE(VerifyStore(o.output).faults.empty());
  EXPECT_TRUE(TempIsEmpty());
}

// In a series (sorted by ID) the outlier is found in the epoch that has it.
TEST_F(IngestOutlierTest, AnOutlierInALaterEpochOfASeriesIsRefusedOrDropped) {
  const auto first = Clustered(8000, 7, 1e4, 1e4);
  auto second = first;
  second[123].x[2] = -2e37;
  const std::string later = WriteRaw(dir_ / "e1.raw", second);
  IngestOptions o = RawOptions({WriteRaw(dir_ / "e0.raw", first), later}, "series");
  ExpectBadInputFrom([&] { Ingest(o); }, {later + ": 1 particle lies far outside the bulk"});
  EXPECT_FALSE(fs::exists(o.output));
  EXPECT_TRUE(TempIsEmpty());

  o.drop_outliers = true;
  const IngestReport report = Ingest(o);
  EXPECT_EQ(report.epochs[0].dropped_points, 0u);
  EXPECT_EQ(report.epochs[1].dropped_points, 1u);
  EXPECT_EQ(report.epochs[0].missing_in_next, 1u);
  EXPECT_EQ(report.epochs[1].points, first.size() - 1);
  EXPECT_LT(Dataset::Open(o.output).cube(1).size, 1.01e4);
}

}  // namespace
}  // namespace octocosm
