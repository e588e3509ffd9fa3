// `octocosm ingest`: snapshots in, a level-of-detail store out, in bounded
// memory. The pipeline, per epoch (PotreeConverter 2's count / chunk / index
// / merge, plus the epoch join):
//
//   1. sort    (series with IDs) read the snapshot once, sorted by ID into
//              temporary runs; the merge join with the next epoch's runs gives
//              each particle its links to the neighbouring epochs
//              (displacements and velocities, ingest/epoch_join.h)
//      bounds  (otherwise) one pass for the bounding box, unless the box is
//              periodic or the cube is given
//   Before either, where the cube is the bounding cube, the positions are
//   surveyed for outliers that would cost the bulk its precision
//   (ingest/outliers.h; in the bounds pass without a sort), and
//   particles outside --clip-box are left out (ingest/clipped_source.h).
//   2. chunk   count on a coarse grid, merge cells into chunks that fit in
//              memory, distribute the points into chunk files (ingest/chunker.h);
//              an epoch that fits in its share of the budget whole is read into
//              memory once instead and chunked in place
//   3. build   each chunk's subtree in memory (index/subtree_builder.h), chunks
//              in parallel; blocks are encoded (index/block_codec.h) and added
//              to the store as they complete
//   4. top     the levels above the chunks, from the chunks' root samples
//   5. ids     the (ID, leaf) pairs, sorted, into the ID index (index/id_index.h)
//
// Nothing half-written survives a failure: the store writers remove their
// files, the temporary directory is removed, and an output directory that this
// run created is removed again.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <utility>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "index/cube.h"
#include "index/dataset.h"
#include "index/dataset_manifest.h"
#include "index/neighbour_radius.h"
#include "index/subtree_builder.h"
#include "ingest/outliers.h"
#include "ingest/rank_group.h"
#include "ingest/snapshot/snapshot_source.h"
#include "storage/manifest.h"
#include "storage/page_file_format.h"

namespace octocosm {

struct IngestOptions {
  std::vector<std::string> inputs;  // one snapshot per epoch, in time order (each may be multi-file)
  std::string output;               // the store directory to create
  ReadOptions read;
  SubtreeOptions tree;
  // The leaves' smoothing lengths, where the snapshot has none of its own:
  // > 0, the radius holding this many nearest neighbours, as the reference
  // renderer draws them (ingest/smoothing_pass.h; a pass over the snapshot
  // before the rest); 0, the leaf's density grid (index/sampler.h step 5):
  // no pass, faster, but not the standard.
  int neighbours = kDefaultNeighbours;
  std::uint64_t memory_budget = 0;  // bytes; 0 = DefaultMemoryBudget()
  std::string temp_dir;             // parent of the temporary directory; "" = inside the output
  std::optional<Cube> cube;         // overrides the periodic box / bounding cube
  // Keep only the particles inside this box, in every epoch (--clip-box).
  std::optional<PositionBox> clip_box;
  // Where an epoch's cube is its bounding cube and outliers would cost the
  // bulk its precision (ingest/outliers.h): drop the particles outside
  // the bulk instead of refusing the epoch (--drop-outliers).
  bool drop_outliers = false;
  unsigned threads = 0;             // 0 = all cores
  std::uint32_t page_size = kDefaultPageSize;
  std::uint64_t max_chunk_points = 0;  // 0 = derived from the memory budget; tests set it to force chunking
  std::uint64_t sort_run_points = 0;   // 0 = derived from the memory budget; tests set it to force merge sorts
  bool stream_chunks = false;          // chunk through buffers and files even when the epoch fits in memory whole (tests)
  bool quiet = false;               // no progress output
};

struct EpochReport {
  std::uint64_t points = 0;          // stored: read_points - dropped_points
  std::uint64_t read_points = 0;     // in the snapshot (of the types read)
  std::uint64_t dropped_points = 0;  // left out by clip_box or drop_outliers
  std::uint64_t nodes = 0;
  std::uint64_t leaves = 0;
  std::uint64_t chunks = 0;
  std::uint64_t spilled_points = 0;  // points that went through temporary chunk files
  bool resident = false;             // held in memory whole and chunked in place (Chunker::SplitResident)
  bool mapped = false;               // resident, mapped from the input files (ResidentEpoch::Map)
  struct Phase {
    std::string name;
    double seconds = 0;      // wall time
    double cpu_seconds = 0;  // CPU time of the whole process (all threads, user and system)
  };
  std::vector<Phase> phases;  // in order
  int depth = 0;
  double mass = 0;
  std::uint64_t missing_in_next = 0;  // particles whose ID the next epoch lacks
  std::uint64_t missing_in_prev = 0;  // particles whose ID the previous epoch lacks
  std::uint64_t duplicate_ids = 0;
  // The (ID, leaf) pairs went through the external sorter: some ID came
  // twice, or the IDs' range needs more than the pairs' share of the budget
  // at 4 bytes a value (ingest/dense_id_table.h).
  bool ids_sorted = false;
  std::optional<EpochLink> to_next;   // every epoch but the last of a series with IDs
};

struct IngestReport {
  std::vector<EpochReport> epochs;
  std::uint64_t input_points = 0;    // stored, over all epochs
  std::uint64_t read_points = 0;     // read, over all epochs
  std::uint64_t dropped_points = 0;  // read but left out (clip_box, drop_outliers)
  std::uint64_t store_bytes = 0;
  std::uint64_t max_chunk_points = 0;
  std::uint64_t memory_budget = 0;
  double seconds = 0;
};

// Several processes ingest one series together (tools/ingest_ranks.h runs
// them under mpirun): each ingests a share of the epochs into a part, whose
// page files the process holding the output adopts (IngestAssembly). The
// store is the one Ingest() writes from the same inputs and options: the
// same blocks, the same manifests but for the store ids. A share's first
// epoch is joined to the epoch before it, read again for its links.
struct IngestShare {
  std::size_t first_epoch = 0, end_epoch = 0;   // [first, end) of IngestOptions::inputs
  std::uint64_t store_id = 0, id_store_id = 0;  // the store's and its ID index's (IngestAssembly)
};

struct IngestPart {
  std::string directory;                     // its page files; the ID index's in ids/
  std::vector<EpochInfo> epochs, id_epochs;  // as StoreWriter::FinishPart gave them
  std::vector<EpochRecord> records;          // the dataset manifest's records of these epochs
  IngestReport report;

  // For sending between processes: exact, doubles included.
  nlohmann::json ToJson() const;
  // kCorruption naming `what` when a member is missing or of the wrong type.
  static IngestPart FromJson(const nlohmann::json& json, const std::string& what);
};

// Ingests the epochs of `share` into `part_directory` (created; removed
// again on failure). Nothing of it is a store until adopted.
IngestPart IngestShareInto(const IngestOptions& options, const IngestShare& share, const std::string& part_directory);

// One epoch spread over the processes of `group` (tools/ingest_ranks.h):
// each rank reads a share of the snapshot's batches, sends each particle to
// the rank whose domains hold it (ingest/epoch_domains.h), in rounds of a
// batch a rank, and builds its domains' subtrees into its part; rank 0
// merges the levels above the domains. Each rank writes the ID index's
// buckets of a run of IDs (ingest/spread_id_index.h) and copies its blocks
// and buckets into rank 0's part, which is then the part IngestShareInto
// writes for the same share. Every rank screens the whole epoch; the
// neighbour pass is shared (each rank reads a share of the snapshot and
// searches a share of its regions). For a series of one epoch, `share`
// its only one; every rank calls it. Returns the part on rank 0; on the
// others an empty one (no epochs), whose directory rank 0 reads from until
// it returns.
IngestPart IngestSpreadInto(const IngestOptions& options, const IngestShare& share, RankGroup& group,
                            const std::string& part_directory);

// The output of an ingest by several processes: takes the output directory
// as Ingest() does (a store's lock, removed on failure where this made it),
// fixes the store ids the shares write under, and assembles their parts.
class IngestAssembly {
 public:
  // For an ingest in `parts` parts.
  IngestAssembly(const IngestOptions& options, std::size_t parts);
  ~IngestAssembly();
  IngestAssembly(const IngestAssembly&) = delete;
  IngestAssembly& operator=(const IngestAssembly&) = delete;

  // The ids that every share writes under.
  std::uint64_t store_id() const;
  std::uint64_t id_store_id() const;  // 0 without IDs
  // Adopts the parts' epochs in order, writes the manifests, and removes
  // the part directories. The parts must cover the epochs in order.
  IngestReport Assemble(const std::vector<IngestPart>& parts);

  // Share `part` of `parts` of a series of `epochs`: consecutive epochs, as
  // even as they divide; empty where there are more parts than epochs.
  // Without the store ids.
  static IngestShare Share(std::size_t epochs, std::size_t part, std::size_t parts);
  // Where part `part` goes: inside the output, so that adopting it is a rename.
  static std::string PartDirectory(const std::string& output, std::size_t part);

 private:
  struct Output;
  const IngestOptions& options_;
  std::unique_ptr<Output> output_;
};

// Half of the physical memory, at least 256 MiB: "a safe fraction of RAM".
std::uint64_t DefaultMemoryBudget();

// Runs the whole pipeline. Throws Error (kBadInput for malformed snapshots,
// kInvalidArgument for bad options, kIo for the disk) after cleaning up.
IngestReport Ingest(const IngestOptions& options);

}  // namespace octocosm
