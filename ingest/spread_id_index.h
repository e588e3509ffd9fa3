// The ID index of an epoch spread over ranks (IngestSpreadInto), built by
// all of them: each rank owns a run of consecutive IDs, receives every
// rank's (ID, leaf) pairs of that run, in rounds of bounded size
// (RankGroup::Exchange), and writes that run's buckets into its own ID
// store's epoch; rank 0 adds the directory and the leaf table. The buckets
// equal those one process writes of the same leaves (index/id_index.h), so
// no rank reads or writes more than its share of the IDs.
//
// Table epochs (unique IDs in a compact range) are cut at bucket boundaries
// into equal runs of buckets; the leaf table, in key order, is gathered on
// every rank first, so that a pair carries its leaf's ordinal. Pairs epochs
// are cut at IDs sampled from every rank's leaves, sorted out of core on the
// rank that owns them, and each rank's first pairs that belong to a bucket
// begun on an earlier rank go to that rank, so that buckets fall where one
// process's do.
#pragma once

#include <cstdint>
#include <cstdio>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "base/mutex.h"
#include "index/morton.h"
#include "ingest/rank_group.h"
#include "storage/store_writer.h"

namespace octocosm {

// A particle ID and what the ID index keeps of its leaf, as the index's
// sorts (ExternalSorter, by `key`) and the ranks' messages carry it: the
// leaf's key, or its ordinal in the leaf table where a spread epoch's index
// is a table.
struct IdLeafRecord {
  std::uint64_t key;  // the particle ID
  std::uint64_t leaf;
};

// The IDs of the leaves a rank builds, in a file of its own: per leaf its
// key, the number of its IDs and the IDs. Leaves may be added from several
// threads at once.
class LeafIdsFile {
 public:
  explicit LeafIdsFile(std::string path);
  ~LeafIdsFile();
  LeafIdsFile(const LeafIdsFile&) = delete;
  LeafIdsFile& operator=(const LeafIdsFile&) = delete;

  void Add(NodeKey leaf, std::span<const std::uint64_t> ids) EXCLUDES(mutex_);
  // Ends the writing; the file stays until the object goes.
  void Close() EXCLUDES(mutex_);
  const std::string& path() const { return path_; }
  // Once closed: the leaves' keys, in the order added, and their IDs in all.
  const std::vector<std::uint64_t>& leaves() const NO_THREAD_SAFETY_ANALYSIS { return leaves_; }
  std::uint64_t id_count() const NO_THREAD_SAFETY_ANALYSIS { return id_count_; }
  // Once closed: every stride-th ID in the order added, the stride doubled
  // whenever they reach twice kSamples, so between kSamples and twice that
  // many (all of them when fewer): where the ranks' runs of IDs are cut.
  static constexpr std::size_t kSamples = 1024;
  const std::vector<std::uint64_t>& samples() const NO_THREAD_SAFETY_ANALYSIS { return samples_; }

  // Every leaf of the file, in the order added.
  void ForEach(const std::function<void(NodeKey, std::span<const std::uint64_t>)>& visit) const;

 private:
  std::string path_;
  Mutex mutex_;
  std::FILE* file_ GUARDED_BY(mutex_);
  std::vector<std::uint64_t> leaves_ GUARDED_BY(mutex_);
  std::uint64_t id_count_ GUARDED_BY(mutex_) = 0;
  std::vector<std::uint64_t> samples_ GUARDED_BY(mutex_);
  std::uint64_t sample_stride_ GUARDED_BY(mutex_) = 1;
};

struct SpreadIdIndexOptions {
  std::uint32_t page_size = 64 * 1024;  // the ID index's
  // Unique IDs in [table_first, table_first + table_span), as the census
  // found them on every rank: table buckets; otherwise pairs.
  bool table = false;
  std::uint64_t table_first = 0, table_span = 0;
  std::size_t round_pairs = 65536;  // pairs a rank sends in one round at most
  std::string temp_prefix;          // the pairs' sort runs: temp_prefix + "-run-N"
  std::uint64_t sort_memory = 64 << 20;  // bytes of pairs sorted in memory at once
  // Called on rank 0 with the smallest ID given to two particles, whichever
  // rank found it; throws (else an Error::BadInput naming the leaves' file).
  std::function<void(std::uint64_t id)> refuse_repeated_id;
};

// Collective: every rank of `group` calls it once its leaves are built and
// `leaf_ids` closed, with the epoch of its own ID store `ids` open. Writes
// this rank's buckets into `ids`, and on rank 0 the directory of every
// rank's buckets and the leaf table; a rank's blocks are then copied into
// rank 0's page file (StoreWriter::ReserveBlocksOf) to make the epoch's index.
// When the leaves give an ID twice, rank 0 throws (options.refuse_repeated_id),
// so that the ingest ends from the rank that removes the output, and the
// others return without writing the rest of their share: they are ended
// with it.
void WriteSpreadIdIndex(RankGroup& group, const LeafIdsFile& leaf_ids, StoreWriter& ids,
                        const SpreadIdIndexOptions& options);

}  // namespace octocosm
