// The particle-ID index: for every epoch, which leaf node holds each particle
// ID, so that a particle is found in any epoch without scanning the data (the
// leaf block's ID column then gives its position).
//
// It is kept in its own store (the subdirectory `ids/` of a dataset store),
// one epoch per epoch of the dataset, so it gets the page file's checksums,
// crash safety and index for free. Within an epoch:
//   - bucket blocks, keys 0, 1, 2, ...: the (ID, leaf key) pairs sorted by ID,
//     as many per bucket as fill one page (the last may hold fewer);
//   - the directory block, key kIdIndexDirectoryKey: the first ID of every
//     bucket, so a look-up reads the (cached) directory and one bucket.
// Block payloads (little endian):
//   bucket:    u32 magic "OCIB", u32 version 1, u64 pair count n, then n x (u64 id, u64 leaf key)
//   directory: u32 magic "OCID", u32 version 1, u64 bucket count b, u64 total pairs, then b x u64 first id
// Duplicate IDs (a malformed input) are all kept; a look-up returns the first.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "index/morton.h"
#include "storage/store_reader.h"
#include "storage/store_writer.h"

namespace octocosm {

inline constexpr std::uint64_t kIdIndexDirectoryKey = ~std::uint64_t{0};

// Writes one epoch of the ID index into a StoreWriter whose epoch is open.
class IdIndexEpochWriter {
 public:
  // Buckets of (page_size - 16) / 16 pairs fill one page each.
  IdIndexEpochWriter(StoreWriter& store, std::uint32_t page_size);
  // Pairs must arrive in non-decreasing ID order.
  void Add(std::uint64_t id, NodeKey leaf);
  // Writes the last bucket and the directory.
  void Finish();

 private:
  void FlushBucket();

  StoreWriter& store_;
  std::size_t bucket_pairs_;
  Bytes bucket_;                 // the bucket block being filled
  std::size_t bucket_fill_ = 0;  // pairs in it
  std::vector<std::uint64_t> first_ids_;
  std::uint64_t total_ = 0;
  std::uint64_t last_id_ = 0;
  bool finished_ = false;
};

// Looks IDs up; thread-safe. Directories are decoded once per epoch and kept.
class IdIndexReader {
 public:
  // Opens `directory` (the `ids/` store). Throws as StoreReader::Open.
  explicit IdIndexReader(const std::string& directory);

  std::uint32_t epoch_count() const { return store_.epoch_count(); }
  // The leaf holding `id` in `epoch`, or nullopt when the epoch has no such ID.
  std::optional<NodeKey> Find(std::uint32_t epoch, std::uint64_t id) const;

 private:
  struct Directory {
    std::vector<std::uint64_t> first_ids;
    std::uint64_t total = 0;
  };
  const Directory& DirectoryOf(std::uint32_t epoch) const;

  StoreReader store_;
  mutable std::mutex mutex_;
  mutable std::unordered_map<std::uint32_t, std::unique_ptr<Directory>> directories_;
};

}  // namespace octocosm
