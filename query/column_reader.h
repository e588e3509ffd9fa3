// Reads only some columns of a block: the header and directory with one
// ranged read, then each run of adjacent wanted columns with one ranged read,
// every column verified by its own checksum (index/block_codec.h). A block
// small enough to arrive whole with the header read costs one read; asking
// for every column reads the whole block once.
#pragma once

#include <cstdint>

#include "base/mutex.h"
#include "index/block_codec.h"
#include "index/dataset.h"
#include "storage/block_source.h"

namespace octocosm {

struct ReadCounters {
  std::uint64_t blocks = 0;  // blocks touched
  std::uint64_t reads = 0;   // positioned reads issued
  std::uint64_t bytes = 0;   // bytes read
};

// Decodes the columns in `wanted` of the block `entry` of `epoch`. Wanted
// optional columns the block lacks come back empty. Throws Error::Corruption
// (naming the file, epoch and block) when the header, a wanted column or a
// required column's presence is wrong, Error::Io when the OS fails.
DecodedBlock ReadBlockColumns(const Dataset& dataset, std::uint32_t epoch, const IndexEntry& entry, ColumnSet wanted,
                              ReadCounters& counters);

// The same reads, but returns the wanted columns undecoded, as a block of
// their own (AssembleColumnSubset): each column checksum-verified, nothing
// decoded, for a consumer that decodes elsewhere (the GPU).
Bytes ReadBlockSubset(const Dataset& dataset, std::uint32_t epoch, const IndexEntry& entry, ColumnSet wanted,
                      ReadCounters& counters);

// A BlockSource of column subsets (ReadBlockSubset), so that a BlockCache and
// a Prefetcher can hold and fetch them. Thread-safe; counts what it read.
class ColumnSubsetSource : public BlockSource {
 public:
  ColumnSubsetSource(const Dataset& dataset, ColumnSet wanted) : dataset_(dataset), wanted_(wanted) {}
  Bytes ReadBlock(const BlockId& id) const override EXCLUDES(mutex_);
  // As the store's: a store on a server reads blocks near one another with
  // one request, whole, and the wanted columns are taken out of them.
  bool CoalescesReads() const override;
  std::optional<BlockExtent> Locate(const BlockId& id) const override;
  void ReadBlocks(std::span<const BlockId> ids, std::span<Bytes> buffers) const override EXCLUDES(mutex_);
  ColumnSet wanted() const { return wanted_; }
  ReadCounters counters() const EXCLUDES(mutex_);

 private:
  const Dataset& dataset_;
  ColumnSet wanted_;
  mutable Mutex mutex_;
  mutable ReadCounters counters_ GUARDED_BY(mutex_);
};

}  // namespace octocosm
