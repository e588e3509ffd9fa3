// Writes a store (docs/FORMAT.md section 1): one page file per epoch, then
// the manifest. The store becomes valid only when Finish() has renamed the
// manifest into place; a writer destroyed before that removes every file it
// created (temporary ones and finished page files), so an interrupted ingest
// leaves nothing that could be mistaken for a store.
//
// A writer killed outright removes nothing. So while it writes, the directory
// holds a lock file (kWriterLockFileName) that the writer keeps locked
// (flock; the kernel releases it when the process dies, however it dies). A
// later writer into the same directory that finds the lock file unlocked
// knows the store as abandoned and removes what it left (RemoveUnfinishedStore)
// before it starts.
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

// Present while a writer works on the directory (docs/FORMAT.md 1.1).
inline constexpr char kWriterLockFileName[] = "incomplete.lock";

// Removes what an unfinished writer leaves in `directory`: page files and
// temporary files, subdirectories that hold nothing but those (a nested store
// such as the ID index's, finished or not), and last the writer's lock file.
// Leaves every other file alone, and does nothing where manifest.json exists
// (a finished store). Does not look at the lock: for a caller that knows the
// writer is gone, or is the writer. Never throws.
void RemoveUnfinishedStore(const std::string& directory) noexcept;

struct StoreWriterOptions {
  std::uint32_t page_size = kDefaultPageSize;
  // 0: draw a random id (the normal case). Tests fix it to build two stores
  // that differ in nothing else.
  std::uint64_t store_id = 0;
  // The number of the first epoch this writer writes. Above 0 for a part of
  // a store that several processes write (FinishPart, AdoptEpochs): each
  // writes a share of the epochs under their final numbers and the store's
  // id, and one of them adopts the others' page files.
  std::uint32_t first_epoch = 0;
};

class StoreWriter {
 public:
  // Creates `directory` if needed. If it holds an abandoned unfinished store
  // (its lock file unlocked), removes that first. kInvalidArgument if another
  // writer is at work there, if it holds store files without that lock file
  // (manifest.json or epoch page files, finished or temporary), if the page
  // size is invalid, or if `dataset` is not a JSON object.
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
  // Makes room in the current epoch for the blocks of `source`, a finished
  // page file, to be copied in as they are at the returned offset of
  // open_epoch_temporary_path() (see PageFileWriter::ReserveBlocksOf).
  std::uint64_t ReserveBlocksOf(const PageFileReader& source);
  // The file the current epoch is written to until EndEpoch.
  std::string open_epoch_temporary_path() const;
  // Finishes the current epoch's page file (durable, under its final name).
  void EndEpoch();
  // Replaces the dataset metadata (a JSON object) that Finish() will write:
  // a writer learns some of it (per-epoch statistics) only while writing.
  void SetDataset(nlohmann::json dataset);
  // Writes the manifest; the store is complete and opens from now on. An
  // epoch still open is an error (kInvalidArgument): end it first.
  void Finish();

  // For a part (StoreWriterOptions::first_epoch): ends without a manifest,
  // leaving the page files for the store's writer to adopt, and returns
  // them. From now on the writer removes nothing; whoever holds the part's
  // directory removes what is never adopted.
  std::vector<EpochInfo> FinishPart();
  // Moves the page files of `epochs` (from a part's FinishPart, in order)
  // from `part_directory` into this store as its next epochs. Checks that
  // each file is there with its size, this store's id and the epoch's
  // number: kInvalidArgument otherwise. Removed again, like this writer's
  // own, if the store is never finished.
  void AdoptEpochs(const std::string& part_directory, const std::vector<EpochInfo>& epochs);

  std::uint64_t store_id() const { return manifest_.store_id; }
  // Bytes written to all files so far, the manifest included once written.
  std::uint64_t bytes_written() const;
  const std::string& directory() const { return directory_; }

 private:
  void RequireUnfinished(const char* operation) const;
  void RemoveCreatedFiles() noexcept;
  void RemoveAbandonedWrite();
  void LockDirectory();
  void UnlockDirectory() noexcept;

  const std::string directory_;
  Manifest manifest_;
  std::uint32_t first_epoch_ = 0;
  std::optional<PageFileWriter> epoch_writer_;
  std::optional<EpochInfo> open_epoch_;
  std::vector<std::string> created_files_;  // finished page files, removed if never committed
  std::uint64_t finished_bytes_ = 0;
  bool finished_ = false;
  bool created_directory_ = false;
  int lock_fd_ = -1;  // holds the flock on kWriterLockFileName
};

}  // namespace octocosm
