// The chunk gatherer (ingest/chunk_gatherer.h): copies exactly the
// points a resident chunk lists, every column, grouped by cells below the
// chunk, from wide and narrow resident columns alike, and its buffers serve
// one chunk after another. (Its cells come from a product, not a division:
// a point within rounding of a cell face could sort with the cell beside
// it; none of these random points lies that close to a face.)
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <memory>
#include <random>
#include <string>

#include "base/error.h"
#include "index/subtree_builder.h"
#include "ingest/chunk_gatherer.h"

namespace octocosm {
namespace {

const Cube kCube{{0, 0, 0}, 100, false};

// `n` points in the cube with every column but the epoch links; IDs 1..n, the
// other columns derived from the index so that a mix-up shows. `narrow`:
// float positions and one mass per type, which a ResidentEpoch keeps narrow.
ParticleChunk Resident(std::size_t n, bool with_velocity, bool narrow = false) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> anywhere(0, 100);
  ParticleChunk points;
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      const double x = anywhere(rng);
      points.position.push_back(narrow ? static_cast<float>(x) : x);
    }
    points.mass.push_back(narrow ? 1.0 + static_cast<double>(i % 6) / 3 : 1.0 + static_cast<double>(i));
    points.type.push_back(static_cast<std::uint8_t>(i % 6));
    points.id.push_back(i + 1);
    if (with_velocity) {
      for (int a = 0; a < 3; ++a) points.velocity.push_back(static_cast<float>(3 * i + a));
    }
  }
  return points;
}

// `points` held as a resident epoch.
ResidentEpoch Hold(const ParticleChunk& points) {
  ResidentEpoch epoch;
  ParticleColumns columns;
  columns.id = points.has_id();
  columns.vector(VectorColumn::kVelocity) = points.has_velocity();
  epoch.Reserve(points.size(), columns);
  epoch.Append(points);
  return epoch;
}

// A chunk for node `key` listing `points`.
Chunk Listing(NodeKey key, const std::vector<std::uint32_t>& points) {
  Chunk chunk;
  chunk.key = key;
  std::shared_ptr<std::uint32_t[]> list = std::make_shared_for_overwrite<std::uint32_t[]>(points.size());
  std::copy(points.begin(), points.end(), list.get());
  chunk.resident = {list.get(), points.size()};
  chunk.resident_lists = std::move(list);
  chunk.point_count = points.size();
  return chunk;
}

// The resident points that lie in node `key`, last one first (any order is
// allowed).
std::vector<std::uint32_t> PointsIn(const ParticleChunk& resident, NodeKey key) {
  std::vector<std::uint32_t> points;
  for (std::size_t i = resident.size(); i-- > 0;) {
    if (kCube.Holds(key, &resident.position[3 * i])) points.push_back(static_cast<std::uint32_t>(i));
  }
  return points;
}

Chunk ChunkOf(const ParticleChunk& resident, NodeKey key) { return Listing(key, PointsIn(resident, key)); }

// Checks that `gathered` holds exactly the points `chunk` lists, each with
// all its columns, grouped by their cell `depth` levels below the chunk
// (Morton order), in list order within a cell.
void ExpectGathered(const ParticleChunk& resident, const Chunk& chunk, const ParticleChunk& gathered, int depth) {
  ASSERT_EQ(gathered.size(), chunk.resident.size());
  ASSERT_EQ(gathered.position.size(), 3 * gathered.size());
  ASSERT_EQ(gathered.type.size(), gathered.size());
  ASSERT_EQ(gathered.id.size(), gathered.size());
  ASSERT_EQ(gathered.velocity.size(), resident.velocity.empty() ? 0 : 3 * gathered.size());
  std::map<std::uint64_t, std::size_t> place_in_list;  // ID -> its place in the chunk's list
  for (std::size_t k = 0; k < chunk.resident.size(); ++k) place_in_list[resident.id[chunk.resident[k]]] = k;
  std::uint64_t previous_cell = 0;
  std::size_t previous_place = 0;
  for (std::size_t j = 0; j < gathered.size(); ++j) {
    const auto found = place_in_list.find(gathered.id[j]);
    ASSERT_NE(found, place_in_list.end()) << "point " << j << " (ID " << gathered.id[j] << ") is not listed";
    const std::size_t place = found->second;
    place_in_list.erase(found);
    const std::size_t i = chunk.resident[place];
    EXPECT_EQ(gathered.mass[j], resident.mass[i]);
    EXPECT_EQ(gathered.type[j], resident.type[i]);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(gathered.position[3 * j + a], resident.position[3 * i + a]);
    if (!resident.velocity.empty()) {
      for (int a = 0; a < 3; ++a) EXPECT_EQ(gathered.velocity[3 * j + a], resident.velocity[3 * i + a]);
    }
    const std::uint64_t cell = kCube.LeafKey(&gathered.position[3 * j], chunk.key.level() + depth).value();
    if (j > 0) {
      ASSERT_GE(cell, previous_cell) << "point " << j << ": cells in Morton order";
      if (cell == previous_cell) {
        EXPECT_GT(place, previous_place) << "point " << j << ": list order within a cell";
      }
    }
    previous_cell = cell;
    previous_place = place;
  }
}

TEST(ChunkGatherer, CopiesTheListedPointsGroupedByCellsBelowTheChunk) {
  for (const bool narrow : {false, true}) {
    SCOPED_TRACE(narrow ? "narrow columns" : "wide columns");
    const ParticleChunk resident = Resident(40000, true, narrow);
    const ResidentEpoch held = Hold(resident);
    ASSERT_EQ(held.positions_narrow(), narrow);
    ASSERT_EQ(held.masses_per_type(), narrow);
    const Chunk chunk = ChunkOf(resident, NodeKey::Root().Child(5));
    ASSERT_GT(chunk.resident.size(), 1024u);
    ASSERT_LE(chunk.resident.size(), 8192u) << "16 points a cell: three levels below the chunk";
    ChunkGatherer gatherer(kCube, kMaxLevel);
    ExpectGathered(resident, chunk, gatherer.Gather(held, chunk), 3);
  }
}

TEST(ChunkGatherer, BuffersServeTheNextChunk) {
  ChunkGatherer gatherer(kCube, kMaxLevel);
  const ParticleChunk large = Resident(40000, true);
  const ResidentEpoch large_held = Hold(large);
  const Chunk first = ChunkOf(large, NodeKey::Root().Child(2));
  gatherer.Reserve(large_held, first.resident.size() / 2);  // reserved too small: the buffers still grow
  ExpectGathered(large, first, gatherer.Gather(large_held, first), 3);
  // Fewer points, and no velocities: nothing of the first chunk is left.
  const ParticleChunk small = Resident(3000, false);
  const Chunk second = ChunkOf(small, NodeKey::Root().Child(7).Child(1));
  ASSERT_GT(second.resident.size(), 0u);
  ExpectGathered(small, second, gatherer.Gather(Hold(small), second), 1);
}

TEST(ChunkGatherer, StopsOrderingAtTheDepthLimit) {
  const ParticleChunk resident = Resident(5000, false);
  const ResidentEpoch held = Hold(resident);
  const Chunk chunk = ChunkOf(resident, NodeKey::Root().Child(3));
  ChunkGatherer gatherer(kCube, /*max_level=*/2);
  ExpectGathered(resident, chunk, gatherer.Gather(held, chunk), 1);
  ChunkGatherer at_the_limit(kCube, /*max_level=*/1);
  ExpectGathered(resident, chunk, at_the_limit.Gather(held, chunk), 0);
}

TEST(ChunkGatherer, RefusesIndicesPastTheSet) {
  const ParticleChunk resident = Resident(1000, false);
  const ResidentEpoch held = Hold(resident);
  ChunkGatherer gatherer(kCube, kMaxLevel);
  std::vector<std::uint32_t> past_the_end = PointsIn(resident, NodeKey::Root().Child(0));
  past_the_end.push_back(1000);
  try {
    gatherer.Gather(held, Listing(NodeKey::Root().Child(0), past_the_end));
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("chunk r0 lists point 1000 of 1000"), std::string::npos) << e.what();
  }
}

// A listed point outside the chunk (which the chunker never lists) is
// gathered into a border cell like the others, and the builder, which checks
// every point against its region, refuses the chunk.
TEST(ChunkGatherer, LeavesAPointOutsideTheChunkForTheBuilderToRefuse) {
  const ParticleChunk resident = Resident(1000, false);
  const ResidentEpoch held = Hold(resident);
  ChunkGatherer gatherer(kCube, kMaxLevel);
  const NodeKey chunk_key = NodeKey::Root().Child(0);
  std::vector<std::uint32_t> listed = PointsIn(resident, chunk_key);
  const std::uint32_t stray = PointsIn(resident, NodeKey::Root().Child(6)).front();
  listed.push_back(stray);
  const ParticleChunk& gathered = gatherer.Gather(held, Listing(chunk_key, listed));
  ASSERT_EQ(gathered.size(), listed.size());
  EXPECT_EQ(std::count(gathered.id.begin(), gathered.id.end(), resident.id[stray]), 1);
  SubtreeOptions options;
  options.capacity = 64;
  try {
    BuildSubtree(gathered, chunk_key, kCube, options, [](NodeKey, const NodePoints&) {});
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("lies outside region r0"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace octocosm
