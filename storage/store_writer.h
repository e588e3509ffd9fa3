// Writes a store (docs/FORMAT.md section 1): one page file per epoch, then
// the manifest. The store becomes valid only when Finish() has renamed the
// manifest into place; a writer destroyed before that removes every file it
// created (temporary ones and finished page files), so an interrupted ingest
// leaves nothing that could be mistaken for a store.
//
//   StoreWriter writer(dir, dataset_json, schema_json);
//   writer.BeginEpoch(/*time=*/0.5, /*redshift=*/1.0);
//   writer.AddBlock(key, bytes, point_count);   // any key order
//   writer.EndEpoch();
//   writer.Finish();
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "storage/manifest.h"
#include "storage/page_file_format.h"
#include "storage/page_file_writer.h"

namespace octocosm {

struct StoreWriterOptions {
  std::uint32_t page_size = kDefaultPageSize;
  // 0: draw a random id (the normal case). Tests fix it to build two stores
  // that differ in nothing else.
  std::uint64_t store_id = 0;
};

class StoreWriter {
 public:
  // Creates `directory` if needed. kInvalidArgument if it already holds store
  // files (manifest.json or epoch page files, finished or temporary), if the
  // page size is invalid, or if `dataset` is not a JSON object.
  StoreWriter(std::string directory, nlohmann::json dataset, nlohmann::json attribute_schema,
              StoreWriterOptions options = {});
  StoreWriter(const StoreWriter&) = delete;
  StoreWriter& operator=(const StoreWriter&) = delete;
  ~StoreWriter();

  // Starts the next epoch (numbered from 0) and returns its number. `time`
  // and `redshift` must be finite.
  std::uint32_t BeginEpoch(double time, double redshift);
  // Adds a block to the current epoch (see PageFileWriter::AddBlock); may be
  // called from several threads at once, but not beside the other calls.
  void AddBlock(std::uint64_t key, std::span<const std::uint8_t> bytes, std::uint64_t point_count);
  // Finishes the current epoch's page file (durable, under its final name).
  void EndEpoch();
  // Replaces the dataset metadata (a JSON object) that Finish() will write:
  // a writer learns some of it (per-epoch statistics) only while writing.
  void SetDataset(nlohmann::json dataset);
  // Writes the manifest; the store is complete and opens from now on. An
  // epoch still open is an error (kInvalidArgument): end it first.
  void Finish();

  std::uint64_t store_id() const { return manifest_.store_id; }
  // Bytes written to all files so far, the manifest included once written.
  std::uint64_t bytes_written() const;
  const std::string& directory() const { return directory_; }

 private:
  void RequireUnfinished(const char* operation) const;
  void RemoveCreatedFiles() noexcept;

  const std::string directory_;
  Manifest manifest_;
  std::optional<PageFileWriter> epoch_writer_;
  std::optional<EpochInfo> open_epoch_;
  std::vector<std::string> created_files_;  // finished page files, removed if never committed
  std::uint64_t finished_bytes_ = 0;
  bool finished_ = false;
};

}  // namespace octocosm
