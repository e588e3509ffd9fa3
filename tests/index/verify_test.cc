// octocosm verify finds each kind of damage a test inflicts, and nothing in a
// sound store.
#include "index/store_verify.h"

#include <gtest/gtest.h>


#include <filesystem>
#include <functional>
#include <fstream>
#include <random>

#include <nlohmann/json.hpp>

#include "index/block_codec.h"
#include "index/cluster_shape.h"
#include "index/dataset.h"
#include "base/error.h"
#include "tests/support/temp_dir.h"
#include "storage/manifest.h"
#include "storage/store_reader.h"
#include "storage/store_writer.h"
#include "ingest/ingest.h"
#include "tests/storage/storage_test_util.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

bool AnyFaultMentions(const VerifyReport& report, const std::string& text) {
  for (const std::string& fault : report.faults) {
    if (fault.find(text) != std::string::npos) return true;
  }
  return false;
}

std::string AllFaults(const VerifyReport& report) {
  std::string all;
  for (const std::string& fault : report.faults) all += fault + "\n";
  return all;
}

void FlipByte(const fs::path& file, std::uint64_t offset) { storagetest::FlipByte(file.string(), offset, 0x5A); }

class VerifyTest : public ::testing::Test {
 protected:

  // An ingested store of clustered points with IDs.
  std::string IngestedStore() {
    std::mt19937_64 rng(3);
    std::normal_distribution<double> gauss(0.5, 0.1);
    {
      std::ofstream out(dir_ / "in.raw", std::ios::binary);
      for (std::uint64_t i = 1; i <= 20000; ++i) {
        const double record[4] = {gauss(rng), gauss(rng), gauss(rng), 1.0};
        out.write(reinterpret_cast<const char*>(record), sizeof record);
        out.write(reinterpret_cast<const char*>(&i), sizeof i);
      }
    }
    IngestOptions o;
    o.inputs = {(dir_ / "in.raw").string()};
    o.output = (dir_ / "store").string();
    o.read.format = "raw";
    o.read.raw = RawLayout::Parse("xyz:f64,mass:f64,id:u64");
    o.tree.capacity = 500;
    o.page_size = 4096;
    o.quiet = true;
    Ingest(o);
    return o.output;
  }

  // An ingested store of clustered points with velocities, with inner
  // nodes of `coarse`, and the particles' velocities (x,y,z) and masses.
  std::string IngestedStoreWithVelocities(CoarsePoints coarse, std::vector<float>* velocities = nullptr,
                                          std::vector<double>* masses = nullptr) {
    std::mt19937_64 rng(5);
    std::normal_distribution<double> gauss(0.5, 0.1);
    std::normal_distribution<float> velocity(0, 200);
    std::lognormal_distribution<double> mass(0, 0.5);
    const std::string name = coarse == CoarsePoints::kClusters ? "clusters" : "sample";
    {
      std::ofstream out(dir_ / (name + ".raw"), std::ios::binary);
      for (std::uint64_t i = 1; i <= 20000; ++i) {
        const double position[3] = {gauss(rng), gauss(rng), gauss(rng)};
        const float v[3] = {100 + velocity(rng), velocity(rng), -50 + velocity(rng)};
        const double m = mass(rng);
        out.write(reinterpret_cast<const char*>(position), sizeof position);
        out.write(reinterpret_cast<const char*>(v), sizeof v);
        out.write(reinterpret_cast<const char*>(&m), sizeof m);
        out.write(reinterpret_cast<const char*>(&i), sizeof i);
        if (velocities != nullptr) velocities->insert(velocities->end(), v, v + 3);
        if (masses != nullptr) masses->push_back(m);
      }
    }
    IngestOptions o;
    o.inputs = {(dir_ / (name + ".raw")).string()};
    o.output = (dir_ / (name + "-store")).string();
    o.read.format = "raw";
    o.read.raw = RawLayout::Parse("xyz:f64,vel:f32,mass:f64,id:u64");
    o.tree.capacity = 500;
    o.tree.coarse = coarse;
    o.page_size = 4096;
    o.quiet = true;
    Ingest(o);
    return o.output;
  }

  // A hand-built one-epoch store: `nodes` (key, points) with the dataset
  // metadata ingest would write for them (and `flags` besides).
  std::string CraftedStore(const std::vector<std::pair<NodeKey, NodePoints>>& nodes, std::size_t capacity,
                           std::uint64_t leaf_points, const nlohmann::json& flags = nlohmann::json::object()) {
    const Cube cube{{0, 0, 0}, 1.0, false};
    nlohmann::json dataset = {{"capacity", capacity},
                              {"max_level", 21},
                              {"has_id", true},
                              {"id_index", ""},
                              {"epochs", {{{"cube", {{"origin", cube.origin}, {"size", cube.size}, {"periodic", false}}},
                                           {"points", leaf_points}}}}};
    dataset.update(flags);
    const std::string path = (dir_ / "crafted").string();
    StoreWriter writer(path, dataset, nlohmann::json::object());
    writer.BeginEpoch(0, 0);
    for (const auto& [key, points] : nodes) writer.AddBlock(key.value(), EncodeBlock(points, key, cube), points.size());
    writer.EndEpoch();
    writer.Finish();
    return path;
  }

  testing_support::TempDir scratch_{"verify-test"};
  const fs::path dir_ = scratch_.path();
};

// Points spread over a node's cube, ordered by octant, with the given total weight.
NodePoints PointsIn(NodeKey key, std::size_t n, double total_weight) {
  const Cube cube{{0, 0, 0}, 1.0, false};
  const NodeCube node = cube.NodeCubeOf(key);
  NodePoints p;
  std::mt19937_64 rng(key.value());
  std::uniform_real_distribution<double> u(0.01, 0.99);
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) p.position.push_back(node.origin[a] + u(rng) * node.size);
    p.weight.push_back(total_weight / static_cast<double>(n));
    p.smoothing.push_back(node.size / 10);
    p.type.push_back(1);
    p.id.push_back(key.value() * 1000 + i);
  }
  OrderByOctant(p, key, cube);
  return p;
}

TEST_F(VerifyTest, ASoundStoreHasNoFaults) {
  const std::string store = IngestedStore();
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(report.faults.empty()) << AllFaults(report);
  EXPECT_GT(report.blocks_checked, 20u);
  EXPECT_TRUE(report.id_index_checked);
}

TEST_F(VerifyTest, AFlippedBlockByteIsAChecksumFaultNamingTheBlock) {
  const std::string store = IngestedStore();
  std::uint64_t offset = 0;
  std::string path;
  {
    const Dataset dataset = Dataset::Open(store);
    const auto entry = dataset.store().Lookup({0, NodeKey::Root().Child(0).value()}).value_or(
        *dataset.store().Lookup({0, NodeKey::Root().value()}));
    offset = entry.first_page * dataset.store().page_size() + entry.byte_length / 2;
    path = (fs::path(store) / dataset.store().epochs()[0].file).string();
  }
  FlipByte(path, offset);
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(AnyFaultMentions(report, "checksum mismatch")) << AllFaults(report);
  EXPECT_TRUE(AnyFaultMentions(report, "epoch-00000.pages")) << AllFaults(report);
}

TEST_F(VerifyTest, AManifestThatMiscountsTheLeavesIsAFault) {
  const std::string store = IngestedStore();
  const fs::path manifest = fs::path(store) / "manifest.json";
  nlohmann::json json = nlohmann::json::parse(std::ifstream(manifest));
  json["dataset"]["epochs"][0]["points"] = 20001;
  SealManifest(json);
  std::ofstream(manifest) << json.dump();
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(AnyFaultMentions(report, "leaves hold 20000 points, the manifest says 20001")) << AllFaults(report);
}

// Everything the dataset metadata records about the tree is checked against
// the blocks, even where the manifest's checksum was recomputed after an edit.
TEST_F(VerifyTest, AManifestThatMiscountsTheTreeIsAFault) {
  const std::string store = IngestedStore();
  const fs::path manifest = fs::path(store) / "manifest.json";
  const nlohmann::json original = nlohmann::json::parse(std::ifstream(manifest));
  EXPECT_TRUE(VerifyStore(store).faults.empty());
  const nlohmann::json& epoch = original["dataset"]["epochs"][0];
  const std::uint64_t nodes = epoch["nodes"], leaves = epoch["leaves"];
  const int depth = epoch["depth"];
  const double mass = epoch["mass"];
  const std::vector<std::pair<std::function<void(nlohmann::json&)>, std::string>> edits = {
      {[](nlohmann::json& e) { e["nodes"] = e["nodes"].get<std::uint64_t>() + 1; },
       "the index holds " + std::to_string(nodes) + " nodes, the manifest says " + std::to_string(nodes + 1)},
      {[](nlohmann::json& e) { e["leaves"] = e["leaves"].get<std::uint64_t>() - 1; },
       "the tree has " + std::to_string(leaves) + " leaves, the manifest says " + std::to_string(leaves - 1)},
      {[](nlohmann::json& e) { e["depth"] = e["depth"].get<int>() + 1; },
       "the deepest leaf is at level " + std::to_string(depth) + ", the manifest says " + std::to_string(depth + 1)},
      {[](nlohmann::json& e) { e["mass"] = e["mass"].get<double>() * (1 + 1e-6); }, "the leaves' weights sum to"},
      {[](nlohmann::json& e) { e["mass"] = e["mass"].get<double>() * (1 + 1e-6); }, "the root's weights sum to"},
  };
  for (const auto& [edit, expected] : edits) {
    nlohmann::json json = original;
    edit(json["dataset"]["epochs"][0]);
    SealManifest(json);
    std::ofstream(manifest, std::ios::trunc) << json.dump();
    const VerifyReport report = VerifyStore(store);
    EXPECT_TRUE(AnyFaultMentions(report, expected)) << AllFaults(report);
  }
  EXPECT_GT(mass, 0);
}

// An edit the checksum was not recomputed for (a shifted cube origin, which
// no block could contradict) stops the store from opening at all.
TEST_F(VerifyTest, AnEditedCubeFailsTheManifestChecksum) {
  const std::string store = IngestedStore();
  const fs::path manifest = fs::path(store) / "manifest.json";
  nlohmann::json json = nlohmann::json::parse(std::ifstream(manifest));
  json["dataset"]["epochs"][0]["cube"]["origin"][0] = json["dataset"]["epochs"][0]["cube"]["origin"][0].get<double>() + 1;
  std::ofstream(manifest, std::ios::trunc) << json.dump(2);
  try {
    VerifyStore(store);
    FAIL() << "an edited manifest verified";
  } catch (const Error& error) {
    EXPECT_EQ(error.kind(), ErrorKind::kCorruption);
    EXPECT_NE(std::string(error.what()).find("checksum mismatch"), std::string::npos) << error.what();
    EXPECT_NE(std::string(error.what()).find("manifest.json"), std::string::npos) << error.what();
  }
}

TEST_F(VerifyTest, BlocksWithoutAColumnTheManifestDeclaresAreAFault) {
  const std::string store = IngestedStore();  // no velocities
  const fs::path manifest = fs::path(store) / "manifest.json";
  nlohmann::json json = nlohmann::json::parse(std::ifstream(manifest));
  json["dataset"]["has_velocity"] = true;
  SealManifest(json);
  std::ofstream(manifest) << json.dump();
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(AnyFaultMentions(report, "carries the columns position,weight,smoothing,id,type, the manifest declares "
                                       "position,weight,smoothing,velocity,id,type"))
      << AllFaults(report);
}

// With velocities and clusters, every inner node carries its clusters'
// velocity dispersions and shapes and no leaf does; together with the mean velocities
// they keep the particles' second velocity moment (the kinetic energy)
// through the codec's quantization.
TEST_F(VerifyTest, ClusterNodesCarryVelocityDispersionsAndVerify) {
  std::vector<float> velocities;
  std::vector<double> masses;
  const std::string store = IngestedStoreWithVelocities(CoarsePoints::kClusters, &velocities, &masses);
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(report.faults.empty()) << AllFaults(report);
  const Dataset dataset = Dataset::Open(store);
  const ColumnSet dispersion = ColumnBit(ColumnId::kVelocityDispersion);
  EXPECT_EQ(dataset.cluster_columns(), dispersion | ColumnBit(ColumnId::kShape) | kClusterLinkColumns);
  EXPECT_EQ(dataset.columns(0) & dispersion, 0u) << "not in every block: leaves lack it";
  EXPECT_EQ(dataset.columns() & dispersion, dispersion);
  std::size_t inner = 0, leaves = 0;
  double second_at_root = 0;
  const StoreReader& reader = dataset.store();
  reader.Scan(0, 0, ~std::uint64_t{0}, [&](const IndexEntry& entry) {
    const NodeKey key = NodeKey::FromValue(entry.key);
    bool leaf = true;
    for (int o = 0; o < 8 && key.level() < kMaxLevel; ++o) leaf = leaf && !reader.Lookup({0, key.Child(o).value()});
    const DecodedBlock block = DecodeBlock(reader.ReadBlock({0, entry.key}), kAllColumns, key, dataset.cube(0), "test");
    (leaf ? leaves : inner) += 1;
    EXPECT_EQ(block.points.velocity_dispersion.size(), leaf ? 0 : block.points.size()) << key.Path();
    EXPECT_EQ(block.points.shape.size(), leaf ? 0 : 6 * block.points.size()) << key.Path();
    if (key == NodeKey::Root()) {
      for (std::size_t i = 0; i < block.points.size(); ++i) {
        const float* v = &block.points.velocity[3 * i];
        const double sigma = block.points.velocity_dispersion[i];
        double v2 = 0;
        for (int a = 0; a < 3; ++a) v2 += double{v[a]} * v[a];
        second_at_root += block.points.weight[i] * (v2 + 3 * sigma * sigma);
      }
    }
    return true;
  });
  EXPECT_GT(inner, 5u);
  EXPECT_GT(leaves, 20u);
  double second = 0;
  for (std::size_t i = 0; i < masses.size(); ++i) {
    for (int a = 0; a < 3; ++a) second += masses[i] * double{velocities[3 * i + a]} * velocities[3 * i + a];
  }
  EXPECT_NEAR(second_at_root / second, 1, 2e-3);
}

TEST_F(VerifyTest, DispersionsTheManifestDoesNotDeclareAreAFault) {
  const std::string store = IngestedStoreWithVelocities(CoarsePoints::kClusters);
  const fs::path manifest = fs::path(store) / "manifest.json";
  nlohmann::json json = nlohmann::json::parse(std::ifstream(manifest));
  ASSERT_TRUE(json["dataset"]["has_velocity_dispersion"].get<bool>());
  json["dataset"]["has_velocity_dispersion"] = false;
  SealManifest(json);
  std::ofstream(manifest) << json.dump();
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(AnyFaultMentions(report, "carries the columns position,weight,smoothing,velocity,id,type,"
                                       "velocity_dispersion,shape,child_cluster,refine_bound, the manifest declares "
                                       "position,weight,smoothing,velocity,id,type"))
      << AllFaults(report);
}

TEST_F(VerifyTest, ClusterNodesWithoutTheDeclaredDispersionsAreAFault) {
  // A sample's inner nodes carry none; the manifest is made to say otherwise.
  const std::string store = IngestedStoreWithVelocities(CoarsePoints::kSample);
  const VerifyReport sound = VerifyStore(store);
  EXPECT_TRUE(sound.faults.empty()) << AllFaults(sound);
  const fs::path manifest = fs::path(store) / "manifest.json";
  nlohmann::json json = nlohmann::json::parse(std::ifstream(manifest));
  ASSERT_FALSE(json["dataset"]["has_velocity_dispersion"].get<bool>());
  json["dataset"]["has_velocity_dispersion"] = true;
  SealManifest(json);
  std::ofstream(manifest) << json.dump();
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(AnyFaultMentions(report, "block r: lacks velocity_dispersion, but with capacity 500 and 1 particle "
                                       "type(s) below it its points are clusters"))
      << AllFaults(report);
}

// Which inner nodes hold clusters follows from the capacity and the particle
// types below them: a node that must hold a sample carries no dispersions,
// and a leaf never does.
TEST_F(VerifyTest, DispersionsWhereThePointsCannotBeClustersAreAFault) {
  const NodeKey root = NodeKey::Root();
  const auto with_velocities = [](NodePoints p, std::uint8_t type, bool dispersion) {
    for (std::size_t i = 0; i < p.size(); ++i) {
      p.type[i] = type;
      p.velocity.insert(p.velocity.end(), {static_cast<float>(i), 2.0f, 3.0f});
      if (dispersion) p.velocity_dispersion.push_back(0.5f);
    }
    return p;
  };
  const nlohmann::json flags = {{"has_velocity", true}, {"has_velocity_dispersion", true}};
  // Two types below the root and a capacity of 8: the root's points are a sample.
  const std::string store = CraftedStore({{root, with_velocities(PointsIn(root, 8, 10.0), 1, true)},
                                          {root.Child(0), with_velocities(PointsIn(root.Child(0), 4, 5.0), 1, true)},
                                          {root.Child(7), with_velocities(PointsIn(root.Child(7), 4, 5.0), 2, false)}},
                                         8, 8, flags);
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(AnyFaultMentions(report, "block r: carries velocity_dispersion, but with capacity 8 and 2 particle "
                                       "type(s) below it its points are a sample"))
      << AllFaults(report);
  EXPECT_TRUE(AnyFaultMentions(report, "block r0: carries the columns position,weight,smoothing,velocity,id,type,"
                                       "velocity_dispersion, the manifest declares position,weight,smoothing,velocity,"
                                       "id,type for a leaf"))
      << AllFaults(report);
  EXPECT_FALSE(AnyFaultMentions(report, "block r7")) << AllFaults(report);
}

// An ingested store's cluster links verify; a crafted root's two clusters
// (one in octant 0, one in octant 7, over leaves of four points each) whose
// masses or bounds disagree with their members are faults naming the node.
TEST_F(VerifyTest, ClusterLinksThatDisagreeWithTheMembersAreAFault) {
  const std::string ingested = IngestedStoreWithVelocities(CoarsePoints::kClusters);
  const Dataset dataset = Dataset::Open(ingested);
  EXPECT_EQ(dataset.cluster_columns() & kClusterLinkColumns, kClusterLinkColumns);
  const DecodedBlock root_block =
      DecodeBlock(dataset.store().ReadBlock({0, NodeKey::Root().value()}), kAllColumns | kClusterLinkColumns,
                  NodeKey::Root(), dataset.cube(0), "root");
  EXPECT_EQ(root_block.points.refine_bound.size(), 3 * root_block.points.size());
  EXPECT_GE(root_block.points.child_cluster.size(), root_block.points.size());

  const NodeKey root = NodeKey::Root();
  const auto clusters = [](double mass_a, float radius) {
    NodePoints p;
    p.position = {0.25, 0.25, 0.25, 0.75, 0.75, 0.75};
    p.weight = {mass_a, 10.0 - mass_a};
    p.smoothing = {0.1, 0.1};
    p.type = {1, 1};
    p.id = {1, 2};
    for (int c = 0; c < 2; ++c) p.shape.insert(p.shape.end(), kRoundShapeCode.begin(), kRoundShapeCode.end());
    p.child_cluster = {0, 0, 0, 0, 1, 1, 1, 1};
    p.refine_bound = {radius, 1.0f, 20.0f, radius, 1.0f, 20.0f};
    p.octant_offsets = {0, 1, 1, 1, 1, 1, 1, 1, 2};
    return p;
  };
  const nlohmann::json flags = {{"has_shape", true}, {"has_cluster_links", true}};
  const auto crafted = [&](const NodePoints& root_points) {
    fs::remove_all(dir_ / "crafted");
    return VerifyStore(CraftedStore({{root, root_points},
                                     {root.Child(0), PointsIn(root.Child(0), 4, 5.0)},
                                     {root.Child(7), PointsIn(root.Child(7), 4, 5.0)}},
                                    100, 8, flags));
  };
  const VerifyReport sound = crafted(clusters(5.0, 1.0f));
  EXPECT_TRUE(sound.faults.empty()) << AllFaults(sound);
  const VerifyReport heavy = crafted(clusters(6.0, 1.0f));
  EXPECT_TRUE(AnyFaultMentions(heavy, "block r: cluster 0 weighs 6 but its members 5")) << AllFaults(heavy);
  const VerifyReport small = crafted(clusters(5.0, 0.01f));
  EXPECT_TRUE(AnyFaultMentions(small, "block r: the refine bound of cluster 0")) << AllFaults(small);
}

TEST_F(VerifyTest, ADamagedIdIndexIsAFault) {
  const std::string store = IngestedStore();
  const fs::path ids = fs::path(store) / "ids" / "epoch-00000.pages";
  std::uint64_t offset = 0;
  {
    const StoreReader id_store = StoreReader::Open((fs::path(store) / "ids").string());
    const IndexEntry bucket = id_store.Lookup({0, 0}).value();  // the first bucket block
    offset = bucket.first_page * id_store.page_size() + 100;
  }
  FlipByte(ids, offset);
  const VerifyReport report = VerifyStore(store);
  EXPECT_FALSE(report.faults.empty());
  EXPECT_TRUE(AnyFaultMentions(report, "ids")) << AllFaults(report);
}

TEST_F(VerifyTest, WeightsThatDisagreeWithTheChildrenAreAFault) {
  const NodeKey root = NodeKey::Root();
  const std::string store = CraftedStore({{root, PointsIn(root, 8, 11.0)},  // children sum to 10
                                          {root.Child(0), PointsIn(root.Child(0), 4, 5.0)},
                                          {root.Child(7), PointsIn(root.Child(7), 4, 5.0)}},
                                         100, 8);
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(AnyFaultMentions(report, "weights sum to 11")) << AllFaults(report);
}

TEST_F(VerifyTest, AnOrphanNodeIsAFault) {
  const NodeKey root = NodeKey::Root();
  const NodeKey orphan = root.Child(3).Child(5);  // its parent r3 has no block
  const std::string store = CraftedStore({{root, PointsIn(root, 4, 4.0)}, {orphan, PointsIn(orphan, 4, 4.0)}}, 100, 4);
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(AnyFaultMentions(report, "its parent r3 is missing")) << AllFaults(report);
}

TEST_F(VerifyTest, ANodeOverCapacityIsAFault) {
  const NodeKey root = NodeKey::Root();
  const std::string store = CraftedStore({{root, PointsIn(root, 12, 12.0)}}, 10, 12);
  const VerifyReport report = VerifyStore(store);
  EXPECT_TRUE(AnyFaultMentions(report, "exceed the node capacity 10")) << AllFaults(report);
}

TEST_F(VerifyTest, ATruncatedPageFileDoesNotOpen) {
  const std::string store = IngestedStore();
  const fs::path pages = fs::path(store) / "epoch-00000.pages";
  fs::resize_file(pages, fs::file_size(pages) - 4096);
  EXPECT_THROW(VerifyStore(store), Error);
}

}  // namespace
}  // namespace octocosm
