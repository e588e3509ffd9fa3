// What the block cache needs from a store: a thread-safe way to read one
// verified block by (epoch, key). The page-file reader implements it; tests
// implement it in memory.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <vector>

#include "base/error.h"
#include "base/hash.h"

namespace octocosm {

using Bytes = std::vector<std::uint8_t>;

// Identifies a block across a whole store: the epoch (one page file each) and
// the node key (opaque here; index/ gives it meaning).
struct BlockId {
  std::uint32_t epoch = 0;
  std::uint64_t key = 0;

  friend bool operator==(const BlockId&, const BlockId&) = default;
};

struct BlockIdHash {
  std::size_t operator()(const BlockId& id) const noexcept {
    // Keys are dense Morton codes: a plain identity hash would cluster in the low bits.
    return static_cast<std::size_t>(MixBits64(id.key ^ (static_cast<std::uint64_t>(id.epoch) << 58) ^ kGoldenGamma));
  }
};

// Where a block lies in its epoch's file, in bytes.
struct BlockExtent {
  std::uint64_t offset = 0;
  std::uint64_t length = 0;
};

class BlockSource {
 public:
  virtual ~BlockSource() = default;

  // Reads one block, verifies it, and returns its bytes. Safe to call from
  // many threads at once. Throws Error: kNotFound when there is no such block,
  // kCorruption when the bytes fail verification, kIo when the OS fails.
  // Corrupt bytes are never returned.
  virtual Bytes ReadBlock(const BlockId& id) const = 0;

  // The same, into `buffer`, reusing its capacity: a reader that serves many
  // blocks (the cache) recycles evicted buffers this way instead of touching
  // fresh memory for every block. The default allocates.
  virtual void ReadBlock(const BlockId& id, Bytes& buffer) const { buffer = ReadBlock(id); }

  // Reading blocks that lie near one another in a file with one request:
  // worth it where each read is a round trip to a server (storage/http_file.h).
  // A source that says so locates its blocks; the prefetcher then reads the
  // wanted blocks near the one it takes together (storage/read_coalescing.h).
  virtual bool CoalescesReads() const { return false; }
  // Where the block lies; nullopt where not known (it is then read alone).
  virtual std::optional<BlockExtent> Locate(const BlockId& /*id*/) const { return std::nullopt; }
  // Reads several blocks, verified, each into its buffer (reusing its
  // capacity), with as few requests as the source can. Throws as ReadBlock
  // does for the first block that fails; the buffers are then unspecified.
  // The default reads one at a time.
  virtual void ReadBlocks(std::span<const BlockId> ids, std::span<Bytes> buffers) const {
    if (ids.size() != buffers.size()) throw Error::InvalidArgument("ReadBlocks: as many buffers as blocks, please");
    for (std::size_t i = 0; i < ids.size(); ++i) ReadBlock(ids[i], buffers[i]);
  }
};

}  // namespace octocosm
