// The ID index in every bucket form: sorted pairs and tables of 16- or
// 32-bit leaf ordinals (index/id_index.h), written through a real store and
// read back.
#include "index/id_index.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "base/error.h"
#include "storage/coding.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

using testing_support::TempDir;

constexpr std::uint32_t kSmallPage = 4096;  // pair buckets of 255 pairs
// Table buckets: 2036 slots of 16 bits (at most 65535 leaves), else 1018 of 32.
constexpr std::size_t SlotsPerBucket(std::size_t leaves) { return (kSmallPage - 24) / (leaves <= 65535 ? 2 : 4); }

// A store with one epoch whose ID index `fill` writes.
void WriteIndex(const std::string& directory, const std::function<void(StoreWriter&)>& fill) {
  StoreWriter store(directory, nlohmann::json::object(), nullptr, {.page_size = kSmallPage});
  store.BeginEpoch(0, 0);
  fill(store);
  store.EndEpoch();
  store.Finish();
}

NodeKey LeafNumber(int i) { return NodeKey::Root().Child(i % 8).Child(i / 8 % 8); }

ErrorKind KindOf(const std::function<void()>& action) {
  try {
    action();
  } catch (const Error& e) {
    return e.kind();
  }
  ADD_FAILURE() << "no Error thrown";
  return ErrorKind::kIo;
}

std::string MessageOf(const std::function<void()>& action) {
  try {
    action();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(IdIndex, PairsFindEveryIdAndNothingElse) {
  TempDir dir("id-index-pairs");
  WriteIndex(dir.path().string(), [](StoreWriter& store) {
    IdIndexEpochWriter ids(store, kSmallPage);
    for (std::uint64_t id = 0; id <= 2000; id += 2) ids.Add(id, LeafNumber(static_cast<int>(id % 37)));
    ids.Finish();
  });
  IdIndexReader reader(dir.path().string());
  for (std::uint64_t id = 0; id <= 2001; ++id) {
    const std::optional<NodeKey> leaf = reader.Find(0, id);
    if (id % 2 == 1) {
      EXPECT_FALSE(leaf.has_value()) << id;
    } else {
      ASSERT_TRUE(leaf.has_value()) << id;
      EXPECT_EQ(*leaf, LeafNumber(static_cast<int>(id % 37))) << id;
    }
  }
  EXPECT_FALSE(reader.Find(0, 1u << 20).has_value());
}

// `count` leaf keys (repeating: the writer does not ask for distinct ones).
std::vector<std::uint64_t> Leaves(std::size_t count) {
  std::vector<std::uint64_t> leaves(count);
  for (std::size_t i = 0; i < count; ++i) leaves[i] = LeafNumber(static_cast<int>(i % 64)).value();
  return leaves;
}

// Threads looking up IDs in several epochs at once, each epoch's directory
// and leaf table read the first time (outside the reader's lock, so that
// round trips to a server overlap), find what one thread finds.
TEST(IdIndex, ConcurrentLookUpsInManyEpochsAgreeWithOneThread) {
  TempDir dir("id-index-threads");
  constexpr std::uint32_t kEpochs = 6;
  {
    StoreWriter store(dir.path().string(), nlohmann::json::object(), nullptr, {.page_size = kSmallPage});
    for (std::uint32_t e = 0; e < kEpochs; ++e) {
      store.BeginEpoch(e, 0);
      IdIndexEpochWriter ids(store, kSmallPage);
      if (e % 2 == 0) {
        std::vector<std::uint32_t> slots(3000);
        for (std::size_t i = 0; i < slots.size(); ++i) slots[i] = static_cast<std::uint32_t>(1 + (i + e) % 64);
        ids.AddTable(e, slots, Leaves(64));
      } else {
        for (std::uint64_t id = e; id < 3000 + e; ++id) ids.Add(id, LeafNumber(static_cast<int>((id + e) % 37)));
      }
      ids.Finish();
      store.EndEpoch();
    }
    store.Finish();
  }
  std::vector<std::uint64_t> asked;
  for (std::uint64_t id = 0; id < 3100; id += 7) asked.push_back(id);
  std::vector<std::vector<std::optional<NodeKey>>> expected;
  {
    IdIndexReader one(dir.path().string());
    for (std::uint32_t e = 0; e < kEpochs; ++e) expected.push_back(one.FindAll(e, asked));
  }
  for (int round = 0; round < 4; ++round) {
    IdIndexReader shared(dir.path().string());
    std::vector<std::vector<std::optional<NodeKey>>> found(2 * kEpochs);
    std::vector<std::thread> threads;
    for (std::uint32_t t = 0; t < 2 * kEpochs; ++t) {
      threads.emplace_back([&, t] { found[t] = shared.FindAll(t % kEpochs, asked); });
    }
    for (std::thread& thread : threads) thread.join();
    for (std::uint32_t t = 0; t < 2 * kEpochs; ++t) EXPECT_EQ(found[t], expected[t % kEpochs]) << "thread " << t;
  }
}

// FindAll answers like Find for IDs in any order, repeated, absent or beyond
// every bucket, in the order asked, in both bucket forms.
TEST(IdIndex, FindAllAnswersLikeFindInTheOrderAsked) {
  for (const bool table : {false, true}) {
    SCOPED_TRACE(table ? "table" : "pairs");
    TempDir dir("id-index-find-all");
    WriteIndex(dir.path().string(), [&](StoreWriter& store) {
      IdIndexEpochWriter ids(store, kSmallPage);
      if (table) {
        std::vector<std::uint32_t> slots(5000);
        for (std::size_t i = 0; i < slots.size(); ++i) slots[i] = i % 5 == 0 ? 0 : static_cast<std::uint32_t>(1 + i % 64);
        ids.AddTable(10, slots, Leaves(64));
      } else {
        for (std::uint64_t id = 10; id < 5010; id += 2) ids.Add(id, LeafNumber(static_cast<int>(id % 37)));
      }
      ids.Finish();
    });
    IdIndexReader reader(dir.path().string());
    std::vector<std::uint64_t> asked;
    for (std::uint64_t k = 0; k < 3000; ++k) asked.push_back((k * 7919) % 5100);  // scattered, some below and above
    asked.push_back(asked[17]);
    asked.push_back(std::numeric_limits<std::uint64_t>::max());
    const std::vector<std::optional<NodeKey>> found = reader.FindAll(0, asked);
    ASSERT_EQ(found.size(), asked.size());
    std::size_t present = 0;
    for (std::size_t i = 0; i < asked.size(); ++i) {
      EXPECT_EQ(found[i], reader.Find(0, asked[i])) << asked[i];
      present += found[i].has_value();
    }
    EXPECT_GT(present, asked.size() / 3);
    EXPECT_LT(present, asked.size());
    EXPECT_TRUE(reader.FindAll(0, {}).empty());
  }
}

// The version field of bucket 0 of epoch 0.
std::uint32_t FirstBucketVersion(const std::string& directory) {
  return GetU32(StoreReader::Open(directory).ReadBlock({0, 0}).data() + 4);
}

// With 3 leaves the ordinals are 16-bit (bucket version 3); with 65536 they
// are 32-bit (version 2), and the ordinals reach past 2^16.
TEST(IdIndex, TableFindsEveryIdAndLeavesOutEmptyBuckets) {
  for (const std::size_t leaf_count : {std::size_t{3}, std::size_t{65536}}) {
    SCOPED_TRACE(leaf_count);
    TempDir dir("id-index-table");
    const std::uint64_t first = 1000;
    const std::size_t per_bucket = SlotsPerBucket(leaf_count);
    // Three buckets' worth and a bit; the second bucket's whole range is
    // empty, and every seventh ID elsewhere is missing.
    std::vector<std::uint32_t> slots(3 * per_bucket + 100);
    std::vector<std::uint64_t> leaves = Leaves(leaf_count);
    leaves[leaf_count - 1] = LeafNumber(63).Child(5).value();  // the last ordinal leads to a leaf of its own
    for (std::size_t i = 0; i < slots.size(); ++i) {
      const bool in_empty_bucket = i >= per_bucket && i < 2 * per_bucket;
      slots[i] = in_empty_bucket || i % 7 == 3 ? 0 : static_cast<std::uint32_t>(1 + (i * 7919) % leaves.size());
    }
    slots.back() = static_cast<std::uint32_t>(leaf_count);
    WriteIndex(dir.path().string(), [&](StoreWriter& store) {
      IdIndexEpochWriter ids(store, kSmallPage);
      ids.AddTable(first, slots, leaves);
      ids.Finish();
    });
    // Three table buckets, the leaf table and the directory.
    EXPECT_EQ(StoreReader::Open(dir.path().string()).block_count(0), 5u);
    EXPECT_EQ(FirstBucketVersion(dir.path().string()), leaf_count <= 65535 ? 3u : 2u);
    IdIndexReader reader(dir.path().string());
    for (std::size_t i = 0; i < slots.size(); ++i) {
      const std::optional<NodeKey> leaf = reader.Find(0, first + i);
      if (slots[i] == 0) {
        EXPECT_FALSE(leaf.has_value()) << i;
      } else {
        ASSERT_TRUE(leaf.has_value()) << i;
        EXPECT_EQ(leaf->value(), leaves[slots[i] - 1]) << i;
      }
    }
    EXPECT_EQ(reader.Find(0, first + slots.size() - 1), LeafNumber(63).Child(5));
    EXPECT_FALSE(reader.Find(0, 0).has_value());
    EXPECT_FALSE(reader.Find(0, first - 1).has_value());
    EXPECT_FALSE(reader.Find(0, first + slots.size()).has_value());
    EXPECT_FALSE(reader.Find(0, std::numeric_limits<std::uint64_t>::max()).has_value());
  }
}

// A table handed over in 16-bit slots (DenseIdTable's while it is narrow)
// writes the same blocks as the same table in 32-bit slots; with more than
// 65535 leaves too, where the ordinals are widened on the way.
TEST(IdIndex, TableOfSixteenBitSlotsWritesTheSameBlocks) {
  for (const std::size_t leaf_count : {std::size_t{5}, std::size_t{65536}}) {
    SCOPED_TRACE(leaf_count);
    const std::vector<std::uint64_t> leaves = Leaves(leaf_count);
    std::vector<std::uint32_t> wide(2 * SlotsPerBucket(3) + 10);
    for (std::size_t i = 0; i < wide.size(); ++i) wide[i] = i % 5 == 1 ? 0 : static_cast<std::uint32_t>(1 + (i * 7919) % std::min<std::size_t>(leaf_count, 65535));
    const std::vector<std::uint16_t> narrow(wide.begin(), wide.end());
    TempDir wide_dir("id-index-wide"), narrow_dir("id-index-narrow-slots");
    WriteIndex(wide_dir.path().string(), [&](StoreWriter& store) {
      IdIndexEpochWriter ids(store, kSmallPage);
      ids.AddTable(40, std::span<const std::uint32_t>(wide), leaves);
      ids.Finish();
    });
    WriteIndex(narrow_dir.path().string(), [&](StoreWriter& store) {
      IdIndexEpochWriter ids(store, kSmallPage);
      ids.AddTable(40, std::span<const std::uint16_t>(narrow), leaves);
      ids.Finish();
    });
    const StoreReader from_wide = StoreReader::Open(wide_dir.path().string());
    const StoreReader from_narrow = StoreReader::Open(narrow_dir.path().string());
    ASSERT_EQ(from_wide.block_count(0), from_narrow.block_count(0));
    ASSERT_GE(from_wide.block_count(0), 4u);  // two buckets or more, the leaf table, the directory
    for (std::uint64_t b = 0; b + 2 < from_wide.block_count(0); ++b) {
      EXPECT_EQ(from_wide.ReadBlock({0, b}), from_narrow.ReadBlock({0, b})) << b;
    }
    EXPECT_EQ(FirstBucketVersion(narrow_dir.path().string()), leaf_count <= 65535 ? 3u : 2u);
  }
}

// 65535 leaves still fit 16-bit ordinals; one more does not.
TEST(IdIndex, TableOrdinalsNarrowUpTo65535Leaves) {
  for (const std::size_t leaf_count : {std::size_t{65535}, std::size_t{65536}}) {
    SCOPED_TRACE(leaf_count);
    TempDir dir("id-index-narrow");
    std::vector<std::uint64_t> leaves = Leaves(leaf_count);
    leaves[leaf_count - 1] = LeafNumber(63).Child(2).value();
    const std::vector<std::uint32_t> slots = {1, static_cast<std::uint32_t>(leaf_count), 0, 2};
    WriteIndex(dir.path().string(), [&](StoreWriter& store) {
      IdIndexEpochWriter ids(store, kSmallPage);
      ids.AddTable(50, slots, leaves);
      ids.Finish();
    });
    EXPECT_EQ(FirstBucketVersion(dir.path().string()), leaf_count <= 65535 ? 3u : 2u);
    IdIndexReader reader(dir.path().string());
    EXPECT_EQ(reader.Find(0, 50), NodeKey::FromValue(leaves[0]));
    EXPECT_EQ(reader.Find(0, 51), LeafNumber(63).Child(2));
    EXPECT_FALSE(reader.Find(0, 52).has_value());
    EXPECT_EQ(reader.Find(0, 53), NodeKey::FromValue(leaves[1]));
  }
}

TEST(IdIndex, TableReachesTheLargestId) {
  TempDir dir("id-index-top");
  const std::uint64_t top = std::numeric_limits<std::uint64_t>::max();
  const std::vector<std::uint32_t> slots = {1, 0, 1};
  const std::vector<std::uint64_t> leaves = {LeafNumber(5).value()};
  WriteIndex(dir.path().string(), [&](StoreWriter& store) {
    IdIndexEpochWriter ids(store, kSmallPage);
    ids.AddTable(top - 2, slots, leaves);
    ids.Finish();
  });
  IdIndexReader reader(dir.path().string());
  EXPECT_EQ(reader.Find(0, top), LeafNumber(5));
  EXPECT_EQ(reader.Find(0, top - 2), LeafNumber(5));
  EXPECT_FALSE(reader.Find(0, top - 1).has_value());
  EXPECT_FALSE(reader.Find(0, top - 3).has_value());
}

TEST(IdIndex, WriterRefusesMixedFormsAndBadTables) {
  TempDir dir("id-index-refusals");
  WriteIndex(dir.path().string(), [](StoreWriter& store) {
    const std::vector<std::uint32_t> slots = {1, 2};
    const std::vector<std::uint64_t> one_leaf = {LeafNumber(1).value()};
    const std::vector<std::uint64_t> two_leaves = {LeafNumber(1).value(), LeafNumber(2).value()};
    {
      IdIndexEpochWriter ids(store, kSmallPage);
      ids.Add(5, LeafNumber(1));
      EXPECT_EQ(KindOf([&] { ids.AddTable(0, slots, two_leaves); }), ErrorKind::kInvalidArgument);
    }
    {
      IdIndexEpochWriter ids(store, kSmallPage);
      EXPECT_NE(MessageOf([&] { ids.AddTable(0, slots, one_leaf); }).find("ordinal 2"), std::string::npos);
    }
    {
      IdIndexEpochWriter ids(store, kSmallPage);
      const std::vector<std::uint64_t> invalid = {LeafNumber(1).value(), 0};
      EXPECT_NE(MessageOf([&] { ids.AddTable(0, slots, invalid); }).find("invalid leaf key"), std::string::npos);
    }
    {
      IdIndexEpochWriter ids(store, kSmallPage);
      const std::uint64_t past = std::numeric_limits<std::uint64_t>::max();
      EXPECT_NE(MessageOf([&] { ids.AddTable(past, slots, two_leaves); }).find("runs past"), std::string::npos);
    }
  });
  TempDir dir2("id-index-refusals-2");
  WriteIndex(dir2.path().string(), [](StoreWriter& store) {
    IdIndexEpochWriter ids(store, kSmallPage);
    const std::vector<std::uint32_t> slots = {1};
    const std::vector<std::uint64_t> leaves = {LeafNumber(1).value()};
    ids.AddTable(0, slots, leaves);
    EXPECT_EQ(KindOf([&] { ids.Add(7, LeafNumber(1)); }), ErrorKind::kInvalidArgument);
    EXPECT_EQ(KindOf([&] { ids.AddTable(1, slots, leaves); }), ErrorKind::kInvalidArgument);
    ids.Finish();
  });
}

// A table bucket written by hand: u32 magic, u32 version, u64 first ID,
// u64 slot count, the slots (u16 for version 3, else u32).
Bytes TableBucket(std::uint32_t version, std::uint64_t first, const std::vector<std::uint32_t>& slots) {
  const std::size_t width = version == 3 ? 2 : 4;
  Bytes block(24 + width * slots.size());
  PutU32(block.data(), 0x4249434F);
  PutU32(block.data() + 4, version);
  PutU64(block.data() + 8, first);
  PutU64(block.data() + 16, slots.size());
  for (std::size_t i = 0; i < slots.size(); ++i) {
    if (width == 2) {
      PutU16(block.data() + 24 + 2 * i, static_cast<std::uint16_t>(slots[i]));
    } else {
      PutU32(block.data() + 24 + 4 * i, slots[i]);
    }
  }
  return block;
}

Bytes Directory(std::uint64_t first) {
  Bytes block(32);
  PutU32(block.data(), 0x4449434F);
  PutU32(block.data() + 4, 1);
  PutU64(block.data() + 8, 1);
  PutU64(block.data() + 16, 2);
  PutU64(block.data() + 24, first);
  return block;
}

Bytes LeafTable(const std::vector<std::uint64_t>& keys) {
  Bytes block(16 + 8 * keys.size());
  PutU32(block.data(), 0x4C49434F);
  PutU32(block.data() + 4, 1);
  PutU64(block.data() + 8, keys.size());
  for (std::size_t i = 0; i < keys.size(); ++i) PutU64(block.data() + 16 + 8 * i, keys[i]);
  return block;
}

struct Damage {
  std::string name;
  Bytes bucket;
  std::optional<Bytes> leaf_table;
  ErrorKind kind;
  std::string says;
};

TEST(IdIndex, ReaderReportsDamagedTables) {
  const Bytes two_leaves = LeafTable({LeafNumber(1).value(), LeafNumber(2).value()});
  std::vector<Damage> damages;
  for (const std::uint32_t version : {2u, 3u}) {
    const std::string v = "-v" + std::to_string(version);
    damages.push_back({"ordinal-past-table" + v, TableBucket(version, 10, {3, 3}), two_leaves, ErrorKind::kCorruption,
                       "past the leaf table"});
    damages.push_back({"no-leaf-table" + v, TableBucket(version, 10, {1, 2}), std::nullopt, ErrorKind::kCorruption,
                       "missing"});
    damages.push_back({"invalid-leaf" + v, TableBucket(version, 10, {1, 2}), LeafTable({LeafNumber(1).value(), 0}),
                       ErrorKind::kCorruption, "invalid node key"});
    damages.push_back({"short-leaf-table" + v, TableBucket(version, 10, {1, 2}), Bytes(12, 0), ErrorKind::kCorruption,
                       "wrong magic or short"});
    Bytes miscounted = TableBucket(version, 10, {1, 2});
    PutU64(miscounted.data() + 16, 3);
    damages.push_back({"slot-count" + v, miscounted, two_leaves, ErrorKind::kCorruption, "slot count 3"});
  }
  // A version-2 bucket read as 16-bit slots, or the reverse, has the wrong size.
  Bytes wide_as_narrow = TableBucket(2, 10, {1, 2});
  PutU32(wide_as_narrow.data() + 4, 3);
  damages.push_back({"wide-as-narrow", wide_as_narrow, two_leaves, ErrorKind::kCorruption, "slot count 2"});
  Bytes narrow_as_wide = TableBucket(3, 10, {1, 2});
  PutU32(narrow_as_wide.data() + 4, 2);
  damages.push_back({"narrow-as-wide", narrow_as_wide, two_leaves, ErrorKind::kCorruption, "slot count 2"});
  damages.push_back({"version", TableBucket(4, 10, {1, 2}), two_leaves, ErrorKind::kNotSupported, "version 4"});
  for (const Damage& damage : damages) {
    TempDir dir("id-index-" + damage.name);
    WriteIndex(dir.path().string(), [&](StoreWriter& store) {
      store.AddBlock(0, damage.bucket, 2);
      store.AddBlock(kIdIndexDirectoryKey, Directory(10), 2);
      if (damage.leaf_table) store.AddBlock(kIdIndexLeafTableKey, *damage.leaf_table, 0);
    });
    IdIndexReader reader(dir.path().string());
    // Both IDs: the damage shows whichever slot is read.
    for (const std::uint64_t id : {10, 11}) {
      try {
        reader.Find(0, id);
        ADD_FAILURE() << damage.name << ": ID " << id << " found without an error";
      } catch (const Error& e) {
        EXPECT_EQ(e.kind(), damage.kind) << damage.name << ": " << e.what();
        EXPECT_NE(std::string(e.what()).find(damage.says), std::string::npos) << damage.name << ": " << e.what();
        EXPECT_NE(std::string(e.what()).find(dir.path().string()), std::string::npos) << e.what();
      }
    }
  }
}

}  // namespace
}  // namespace octocosm
