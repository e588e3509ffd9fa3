// Reads a store (docs/FORMAT.md section 1): checks the directory and the
// manifest, opens every epoch's page file and checks it against the
// manifest, then serves verified blocks by (epoch, key).
//
// Open reads the manifest and one 128-byte header per epoch, nothing else.
// All methods are safe to call from many threads at once.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "storage/block_source.h"
#include "storage/manifest.h"
#include "storage/page_file_reader.h"

namespace octocosm {

struct StoreReaderOptions {
  // Decoded index pages cached per epoch, besides each root.
  std::size_t index_cache_pages_per_epoch = 64;
};

class StoreReader : public BlockSource {
 public:
  // Throws kNotFound if `directory` is missing or is not a store,
  // kCorruption if the store is unfinished, damaged or inconsistent,
  // kNotSupported for a format this build cannot read, kIo if the OS fails.
  static StoreReader Open(const std::string& directory, StoreReaderOptions options = {});

  StoreReader(StoreReader&&) noexcept = default;
  StoreReader& operator=(StoreReader&&) noexcept = default;

  // BlockSource: the verified bytes of a block. kNotFound for an unknown
  // epoch or key.
  Bytes ReadBlock(const BlockId& id) const override;
  void ReadBlock(const BlockId& id, Bytes& buffer) const override;
  // Where some epoch is on a server.
  bool CoalescesReads() const override { return coalesces_reads_; }
  std::optional<BlockExtent> Locate(const BlockId& id) const override;
  // Blocks of one epoch are read with PageFileReader::ReadBlocksInto (one
  // request from a server); of several, an epoch at a time.
  void ReadBlocks(std::span<const BlockId> ids, std::span<Bytes> buffers) const override;
  // Reads a block into `out` without allocating; returns its length. `out`
  // must hold the block (Lookup tells its byte_length); kInvalidArgument if
  // it does not.
  std::size_t ReadBlockInto(const BlockId& id, std::span<std::uint8_t> out) const;

  // Unverified bytes [offset, offset + out.size()) of a block; see
  // PageFileReader::ReadBlockRange. kNotFound for an unknown block.
  void ReadBlockRange(const BlockId& id, std::uint64_t offset, std::span<std::uint8_t> out) const;

  std::optional<IndexEntry> Lookup(const BlockId& id) const;
  // Visits the entries of `epoch` with keys in [lo, hi], in key order, until
  // `visit` returns false.
  void Scan(std::uint32_t epoch, std::uint64_t lo, std::uint64_t hi,
            const std::function<bool(const IndexEntry&)>& visit) const;

  std::uint32_t epoch_count() const { return static_cast<std::uint32_t>(manifest_.epochs.size()); }
  const std::vector<EpochInfo>& epochs() const { return manifest_.epochs; }
  std::uint64_t block_count(std::uint32_t epoch) const;
  std::uint32_t page_size() const { return manifest_.page_size; }
  std::uint64_t store_id() const { return manifest_.store_id; }
  const nlohmann::json& dataset() const { return manifest_.dataset; }
  const nlohmann::json& attribute_schema() const { return manifest_.attribute_schema; }
  // The manifest as read, including members this version does not know.
  const nlohmann::json& manifest_json() const { return manifest_json_; }
  const std::string& directory() const { return directory_; }
  const PageFileReader& page_file(std::uint32_t epoch) const;

  // Drops every page file from the OS page cache and forgets cached index
  // pages (roots excepted), so the next reads are cold.
  void DropCaches() const;
  // Hints front-to-back reading of every page file.
  void AdviseSequential() const;

  // Summed over all epochs.
  ReaderStats stats() const;

 private:
  StoreReader(std::string directory, nlohmann::json manifest_json, Manifest manifest,
              std::vector<std::unique_ptr<PageFileReader>> page_files);
  // The block's index entry in `file`, its epoch's; kNotFound naming it.
  static IndexEntry Find(const PageFileReader& file, const BlockId& id);

  std::string directory_;
  nlohmann::json manifest_json_;
  Manifest manifest_;
  std::vector<std::unique_ptr<PageFileReader>> page_files_;  // one per epoch
  bool coalesces_reads_ = false;
};

}  // namespace octocosm
