// The particle-ID index: for every epoch, which leaf node holds each particle
// ID, so that a particle is found in any epoch without scanning the data (the
// leaf block's ID column then gives its position).
//
// It is kept in its own store (the subdirectory `ids/` of a dataset store),
// one epoch per epoch of the dataset, so it gets the page file's checksums,
// crash safety and index for free. Within an epoch:
//   - bucket blocks, keys 0, 1, 2, ..., each filling about one page, in one
//     of three forms (an epoch uses one):
//       pairs (version 1): (ID, leaf key) pairs sorted by ID, for IDs in any
//         range;
//       a table (version 2, or 3 while the epoch has at most 65535 leaves):
//         for a run of consecutive IDs, which leaf holds each, as an ordinal
//         into the epoch's leaf table. Simulation codes number particles
//         0..N-1 or so: a quarter of the pairs' bytes (an eighth as 16-bit
//         ordinals), and written straight from the table ingest fills
//         (DenseIdTable);
//   - the directory block, key kIdIndexDirectoryKey: the first ID of every
//     bucket (for a table, the ID of its first slot), so a look-up reads the
//     (cached) directory and one bucket;
//   - with table buckets, the leaf table, key kIdIndexLeafTableKey.
// Block payloads (little endian):
//   bucket, pairs: u32 magic "OCIB", u32 version 1, u64 pair count n, then n x (u64 id, u64 leaf key)
//   bucket, table: u32 magic "OCIB", u32 version 2, u64 first id f, u64 slot count m, then m x u32
//                  ordinal (ID f + i: 0 where no particle has it, else 1 + its leaf's index in the leaf table);
//                  version 3: the same with m x u16 ordinal
//   leaf table:    u32 magic "OCIL", u32 version 1, u64 leaf count l, then l x u64 leaf key
//   directory:     u32 magic "OCID", u32 version 1, u64 bucket count b, u64 total IDs, then b x u64 first id
// Duplicate IDs (a malformed input) are all kept in pairs; a look-up returns
// the first. Tables cannot hold duplicates.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "base/mutex.h"
#include "index/morton.h"
#include "storage/store_reader.h"
#include "storage/store_writer.h"

namespace octocosm {

inline constexpr std::uint64_t kIdIndexDirectoryKey = ~std::uint64_t{0};
inline constexpr std::uint64_t kIdIndexLeafTableKey = ~std::uint64_t{0} - 1;

// The smallest page an ID index store should use (ingest takes the store's
// page size when larger): a bucket fills about one page, and with 4 KiB
// pages 10^8 IDs in 32-bit tables made 98,000 blocks instead of 6,100,
// which took twice as long to write (0.39 s against 0.20 s), while a look-up
// reads one bucket either way.
inline constexpr std::uint32_t kIdIndexMinPageSize = 64 * 1024;

// Writes one epoch of the ID index into a StoreWriter whose epoch is open.
// An epoch may also be written in parts (the ranks of a spread ingest):
// each part holds the buckets of a run of consecutive IDs, numbered from
// its `first_bucket` (AddTableBuckets or Add, then FinishBuckets), and one
// part adds the directory of them all (WriteDirectory) and, for tables, the
// leaf table (WriteLeafTable).
class IdIndexEpochWriter {
 public:
  // Buckets of (page_size - 16) / 16 pairs fill one page each; the first
  // gets the key `first_bucket` (0 unless the epoch is written in parts).
  IdIndexEpochWriter(StoreWriter& store, std::uint32_t page_size, std::uint64_t first_bucket = 0);
  // Pairs must arrive in non-decreasing ID order.
  void Add(std::uint64_t id, NodeKey leaf);
  // The whole epoch as a table instead of pairs: slot i tells which leaf
  // holds ID first_id + i, 0 for none, else 1 + the leaf's index in
  // `leaves`. Written as table buckets of (page_size - 24) / 2 slots of 16
  // bits when `leaves` holds at most 65535 leaves, else (page_size - 24) / 4
  // slots of 32 bits, those with no ID left out: the ordinals go to disk at
  // the end of an ingest, after the last leaf, so half the bytes is half
  // that wait (at 10^8 points, 200 MB instead of 400). Call it once,
  // instead of Add, then Finish. Throws
  // Error::InvalidArgument for an ordinal past `leaves`, an invalid leaf key
  // or IDs past 2^64 - 1. The slots may come 16 or 32 bits wide; the
  // buckets' width depends only on the count of leaves.
  void AddTable(std::uint64_t first_id, std::span<const std::uint32_t> slots, std::span<const std::uint64_t> leaves);
  void AddTable(std::uint64_t first_id, std::span<const std::uint16_t> slots, std::span<const std::uint64_t> leaves);
  // A part of a table: its buckets without the leaf table, for an epoch of
  // `leaf_count` leaves. `first_id` must begin a bucket of the whole table
  // (a multiple of TableBucketSlots from the table's first ID).
  void AddTableBuckets(std::uint64_t first_id, std::span<const std::uint32_t> slots, std::uint64_t leaf_count);
  void AddTableBuckets(std::uint64_t first_id, std::span<const std::uint16_t> slots, std::uint64_t leaf_count);
  // Writes the last bucket and the directory.
  void Finish();
  // Writes the last bucket of a part; the directory is left to WriteDirectory.
  void FinishBuckets();
  // The first ID of each bucket written, and the IDs they hold.
  const std::vector<std::uint64_t>& first_ids() const { return first_ids_; }
  std::uint64_t total() const { return total_; }

  // The directory of an epoch written in parts: every part's first_ids(),
  // in ID order, and the sum of their total().
  static void WriteDirectory(StoreWriter& store, std::span<const std::uint64_t> first_ids, std::uint64_t total);
  // The leaf table of a table epoch (the ordinals' leaves, in their order).
  static void WriteLeafTable(StoreWriter& store, std::span<const std::uint64_t> leaves);
  // IDs a table bucket holds for an epoch of `leaf_count` leaves, and pairs
  // a pairs bucket holds.
  static std::size_t TableBucketSlots(std::uint32_t page_size, std::uint64_t leaf_count);
  static std::size_t BucketPairs(std::uint32_t page_size);

 private:
  template <typename Slot>
  void AddTableOf(std::uint64_t first_id, std::span<const Slot> slots, std::uint64_t leaf_count);
  void FlushBucket();

  StoreWriter& store_;
  std::uint32_t page_size_;
  std::uint64_t first_bucket_;
  std::size_t bucket_pairs_;
  Bytes bucket_;                 // the bucket block being filled
  std::size_t bucket_fill_ = 0;  // pairs in it
  std::vector<std::uint64_t> first_ids_;
  std::uint64_t total_ = 0;
  std::uint64_t last_id_ = 0;
  bool finished_ = false;
  bool has_table_ = false;
};

// Looks IDs up; thread-safe. Directories (and leaf tables) are decoded once
// per epoch and kept.
class IdIndexReader {
 public:
  // Opens `directory` (the `ids/` store). Throws as StoreReader::Open.
  explicit IdIndexReader(const std::string& directory);

  std::uint32_t epoch_count() const { return store_.epoch_count(); }
  // The leaf holding `id` in `epoch`, or nullopt when the epoch has no such ID.
  std::optional<NodeKey> Find(std::uint32_t epoch, std::uint64_t id) const;
  // Find for each of `ids`, in their order, reading each bucket once.
  std::vector<std::optional<NodeKey>> FindAll(std::uint32_t epoch, std::span<const std::uint64_t> ids) const;

 private:
  struct Directory {
    std::vector<std::uint64_t> first_ids;
    std::uint64_t total = 0;
    std::optional<std::vector<std::uint64_t>> leaves;  // the leaf table, once a table bucket needed it
  };
  Directory& DirectoryOf(std::uint32_t epoch) const EXCLUDES(mutex_);  // loaded once, then kept
  const std::vector<std::uint64_t>& LeafTableOf(std::uint32_t epoch) const EXCLUDES(mutex_);
  std::optional<NodeKey> FindInPairs(const Bytes& block, std::uint64_t id, const std::string& where) const;
  // `slot_bytes`: 4 for a version-2 table bucket, 2 for version 3.
  std::optional<NodeKey> FindInTable(std::uint32_t epoch, const Bytes& block, std::uint64_t id, std::size_t slot_bytes,
                                     const std::string& where) const;

  StoreReader store_;
  mutable Mutex mutex_;
  mutable std::unordered_map<std::uint32_t, std::unique_ptr<Directory>> directories_ GUARDED_BY(mutex_);
};

}  // namespace octocosm
