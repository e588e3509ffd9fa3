// The ID index written in parts by the ranks of a spread epoch
// (ingest/spread_id_index.h), on ranks that are threads of this process:
// the ranks' blocks together are the blocks one process writes of the same
// leaves, whatever the number of ranks, the way the leaves lie among them,
// the rounds and the buckets' size; an ID given twice is refused by the rank
// that holds it.
#include "ingest/spread_id_index.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <map>
#include <numeric>
#include <stdexcept>
#include <random>
#include <string>
#include <vector>

#include "index/id_index.h"
#include "storage/store_reader.h"
#include "tests/support/thread_rank_group.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

using testing_support::RunRanks;
using testing_support::TempDir;

// An epoch's leaves: each key with the IDs it holds.
using Leaves = std::map<std::uint64_t, std::vector<std::uint64_t>>;

NodeKey LeafKey(std::uint64_t i) {
  NodeKey key = NodeKey::Root();
  for (int level = 0; level < 7; ++level) key = key.Child(static_cast<int>(i >> (3 * (6 - level)) & 7));
  return key;
}

// `ids` spread over `leaf_count` leaves at random.
Leaves SpreadOverLeaves(const std::vector<std::uint64_t>& ids, std::uint64_t leaf_count, std::mt19937_64& random) {
  Leaves leaves;
  std::uniform_int_distribution<std::uint64_t> pick(0, leaf_count - 1);
  for (const std::uint64_t id : ids) leaves[LeafKey(pick(random)).value()].push_back(id);
  return leaves;
}

std::map<std::uint64_t, Bytes> BlocksOf(const std::string& directory) {
  const StoreReader store = StoreReader::Open(directory);
  std::map<std::uint64_t, Bytes> blocks;
  store.Scan(0, 0, ~std::uint64_t{0}, [&](const IndexEntry& entry) {
    blocks[entry.key] = store.ReadBlock({0, entry.key});
    return true;
  });
  return blocks;
}

void WriteStore(const std::string& directory, const std::function<void(StoreWriter&)>& fill) {
  StoreWriter store(directory, nlohmann::json::object(), nullptr, {.page_size = 4096});
  store.BeginEpoch(0, 0);
  fill(store);
  store.EndEpoch();
  store.Finish();
}

// What one process writes of `leaves`: a table from `table_first` when
// `table`, else sorted pairs.
std::map<std::uint64_t, Bytes> OneProcessIndex(const std::string& directory, const Leaves& leaves, bool table,
                                               std::uint64_t table_first, std::uint64_t table_span,
                                               std::uint32_t page_size) {
  WriteStore(directory, [&](StoreWriter& store) {
    IdIndexEpochWriter writer(store, page_size);
    if (table) {
      std::vector<std::uint64_t> keys;
      std::vector<std::uint32_t> slots(table_span, 0);
      for (const auto& [key, ids] : leaves) {
        keys.push_back(key);
        for (const std::uint64_t id : ids) slots[id - table_first] = static_cast<std::uint32_t>(keys.size());
      }
      writer.AddTable(table_first, std::span<const std::uint32_t>(slots), keys);
    } else {
      std::vector<std::pair<std::uint64_t, std::uint64_t>> pairs;
      for (const auto& [key, ids] : leaves) {
        for (const std::uint64_t id : ids) pairs.push_back({id, key});
      }
      std::sort(pairs.begin(), pairs.end());
      for (const auto& [id, key] : pairs) writer.Add(id, NodeKey::FromValue(key));
    }
    writer.Finish();
  });
  return BlocksOf(directory);
}

// The index the `ranks` write of `leaves`, each leaf on the rank `rank_of`
// it, the ranks' blocks together (a key written twice fails the test).
std::map<std::uint64_t, Bytes> SpreadIndex(const std::string& directory, const Leaves& leaves, int ranks,
                                           const std::function<int(std::uint64_t)>& rank_of,
                                           const SpreadIdIndexOptions& options) {
  RunRanks(ranks, [&](RankGroup& group) {
    const std::string mine = directory + "/rank-" + std::to_string(group.rank());
    std::filesystem::create_directories(mine);
    LeafIdsFile leaf_ids(mine + "/leaf-ids");
    for (const auto& [key, ids] : leaves) {
      if (rank_of(key) == group.rank()) leaf_ids.Add(NodeKey::FromValue(key), ids);
    }
    leaf_ids.Close();
    SpreadIdIndexOptions here = options;
    here.temp_prefix = mine + "/pairs";
    WriteStore(mine + "/ids", [&](StoreWriter& store) { WriteSpreadIdIndex(group, leaf_ids, store, here); });
  });
  std::map<std::uint64_t, Bytes> blocks;
  for (int r = 0; r < ranks; ++r) {
    for (auto& [key, block] : BlocksOf(directory + "/rank-" + std::to_string(r) + "/ids")) {
      EXPECT_TRUE(blocks.emplace(key, std::move(block)).second) << "block " << key << " written twice";
    }
  }
  return blocks;
}

struct Case {
  const char* name;
  bool table;
  std::uint64_t leaf_count;
  std::uint32_t page_size;
  std::size_t round_pairs;
};

TEST(SpreadIdIndex, TheRanksWriteTheBlocksOneProcessWrites) {
  TempDir dir("spread-id-index");
  std::mt19937_64 random(11);
  // Tables: IDs from 5000 with holes, one of them longer than several buckets;
  // pairs: IDs anywhere in 64 bits, some close together.
  std::vector<std::uint64_t> dense;
  for (std::uint64_t id = 5000; id < 5000 + 6000; ++id) {
    if (id % 7 != 3 && (id < 7000 || id > 8200)) dense.push_back(id);
  }
  std::vector<std::uint64_t> sparse;
  std::uniform_int_distribution<std::uint64_t> anywhere;
  for (int i = 0; i < 9000; ++i) sparse.push_back(anywhere(random));
  for (std::uint64_t id = 1000; id < 1500; ++id) sparse.push_back(id);
  std::sort(sparse.begin(), sparse.end());
  sparse.erase(std::unique(sparse.begin(), sparse.end()), sparse.end());

  const Case cases[] = {
      {"table, 16-bit ordinals", true, 40, 256, 97},
      {"table, 16-bit ordinals, one round", true, 300, 4096, 1 << 20},
      {"table, 32-bit ordinals", true, 70000, 512, 1000},
      {"pairs, buckets of 15", false, 60, 256, 13},
      {"pairs, buckets of 4095", false, 60, 64 * 1024, 500},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::vector<std::uint64_t>& ids = c.table ? dense : sparse;
    // 70,000 leaves need more IDs than leaves to hold one each.
    std::vector<std::uint64_t> more_ids;
    if (c.leaf_count > ids.size()) {
      for (std::uint64_t id = 5000; id < 5000 + 2 * c.leaf_count; ++id) more_ids.push_back(id);
    }
    const std::vector<std::uint64_t>& used = more_ids.empty() ? ids : more_ids;
    Leaves leaves;
    if (more_ids.empty()) {
      leaves = SpreadOverLeaves(used, c.leaf_count, random);
    } else {
      for (std::size_t i = 0; i < used.size(); ++i) leaves[LeafKey(i / 2).value()].push_back(used[i]);
    }
    const std::uint64_t first = used.front(), span = used.back() - used.front() + 1;
    const std::map<std::uint64_t, Bytes> want =
        OneProcessIndex((dir.path() / c.name).string() + "-one", leaves, c.table, first, span, c.page_size);
    ASSERT_GT(want.size(), 3u);
    SpreadIdIndexOptions options;
    options.page_size = c.page_size;
    options.table = c.table;
    options.table_first = first;
    options.table_span = span;
    options.round_pairs = c.round_pairs;
    options.sort_memory = 700 * 16;  // several sort runs a rank
    for (int ranks = 1; ranks <= 5; ++ranks) {
      // Leaves dealt out at random, and in runs of consecutive keys as
      // domains are; with 5 ranks, rank 3 holds none.
      const std::function<int(std::uint64_t)> at_random = [&](std::uint64_t key) {
        const int r = static_cast<int>(key * 0x9E3779B97F4A7C15ull >> 60) % ranks;
        return ranks == 5 && r == 3 ? 4 : r;
      };
      std::vector<std::uint64_t> keys;
      for (const auto& leaf : leaves) keys.push_back(leaf.first);
      const std::function<int(std::uint64_t)> in_runs = [&](std::uint64_t key) {
        const std::size_t at = static_cast<std::size_t>(std::lower_bound(keys.begin(), keys.end(), key) - keys.begin());
        return static_cast<int>(at * static_cast<std::size_t>(ranks) / keys.size());
      };
      for (const auto& [how, rank_of] : {std::pair{"at random", at_random}, std::pair{"in runs", in_runs}}) {
        SCOPED_TRACE(std::to_string(ranks) + " ranks, leaves " + how);
        const std::string where = (dir.path() / (std::string(c.name) + "-" + std::to_string(ranks) + how)).string();
        const std::map<std::uint64_t, Bytes> got = SpreadIndex(where, leaves, ranks, rank_of, options);
        EXPECT_EQ(got.size(), want.size());
        EXPECT_TRUE(got == want) << "the blocks differ";
      }
    }
  }
}

TEST(SpreadIdIndex, AnIdGivenTwiceIsRefusedWhicheverRanksHoldTheParticles) {
  TempDir dir("spread-id-index-twice");
  for (const bool table : {true, false}) {
    SCOPED_TRACE(table ? "table" : "pairs");
    Leaves leaves;
    for (std::uint64_t i = 0; i < 4000; ++i) leaves[LeafKey(i % 50).value()].push_back(100 + i);
    leaves[LeafKey(7).value()].push_back(100 + 2345);  // also in leaf 2345 % 50 = 45
    SpreadIdIndexOptions options;
    options.page_size = 256;
    options.table = table;
    options.table_first = 100;
    options.table_span = 4000;
    options.round_pairs = 100;
    options.refuse_repeated_id = [](std::uint64_t id) {
      throw std::invalid_argument("ID " + std::to_string(id) + " given twice");
    };
    for (int ranks : {1, 2, 3}) {
      SCOPED_TRACE(std::to_string(ranks) + " ranks");
      const std::string where = (dir.path() / ((table ? "table-" : "pairs-") + std::to_string(ranks))).string();
      try {
        SpreadIndex(where, leaves, ranks, [&](std::uint64_t key) { return static_cast<int>(key % 3) % ranks; },
                    options);
        ADD_FAILURE() << "no error";
      } catch (const std::invalid_argument& e) {
        EXPECT_STREQ(e.what(), "ID 2445 given twice");
      }
    }
  }
}

}  // namespace
}  // namespace octocosm
