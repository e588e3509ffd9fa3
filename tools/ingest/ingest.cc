#include "tools/ingest/ingest.h"

#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <unordered_set>

#include <nlohmann/json.hpp>

#include "index/block_codec.h"
#include "index/id_index.h"
#include "storage/error.h"
#include "storage/store_writer.h"
#include "tools/ingest/chunk_gatherer.h"
#include "tools/ingest/chunk_queue.h"
#include "tools/ingest/chunker.h"
#include "tools/ingest/clipped_source.h"
#include "tools/ingest/dense_id_table.h"
#include "tools/ingest/epoch_join.h"
#include "tools/ingest/external_sorter.h"
#include "tools/ingest/outliers.h"
#include "tools/ingest/resident_epoch.h"
#include "tools/interrupt_cleanup.h"
#include "tools/progress.h"
#include "tools/smoothing_pass.h"
#include "tools/temp_directory.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

// Bytes of memory one particle costs while its chunk's subtree is built: the
// chunk's columns (about 65 bytes), the octant partition, and the node copies
// handed to the sink and the encoder. Measured peak RSS / chunk points is
// about 120; this leaves room.
constexpr std::uint64_t kBuildBytesPerPoint = 160;

// The most memory chunk buffers take, whatever the budget.
constexpr std::uint64_t kMaxChunkBufferBytes = std::uint64_t{256} << 20;

// The most points a chunk is cut to hold, whatever the budget (unless the
// node capacity asks for more). A chunk's buffers on its build thread (its
// gathered columns and placement records, about 90 bytes a point) are fresh
// memory, whose first touch is the costliest memory access on the virtual
// machines this runs on; chunks this small keep them small and near the
// caches. At 10^7 points (chunks of 1.25 million points before) it cut the
// ingest from 1.51-1.57 s to 1.23-1.45 s and its peak RSS by about 175 MiB;
// at 10^8 it changed little (docs/BENCHMARKS.md).
constexpr std::uint64_t kMaxChunkPoints = std::uint64_t{1} << 18;
// The build threads take chunks from a window of this many per thread
// (tools/ingest/chunk_queue.h), so the last ones built are among the last
// that many; those are cut to at most an eighth of the largest chunk
// (Chunker::SplitTail), a few milliseconds' work each.
constexpr std::size_t kQueueWindowPerThread = 4;
constexpr std::uint64_t kTailChunkFraction = 8;

struct IdLeafRecord {
  std::uint64_t key;  // particle ID
  std::uint64_t leaf;
};

// Removes the output directory on failure, and when a signal ends the
// program (tools/interrupt_cleanup.h), but only if this run created it; in
// a directory that was there before, only the unfinished store's files.
class OutputGuard {
 public:
  explicit OutputGuard(const std::string& path) : path_(path), created_(!fs::exists(path)) {
    if (!created_) return;  // see StoreLocked
    remove_on_interrupt_.emplace([path] {
      std::error_code ignored;
      fs::remove_all(path, ignored);
    });
  }
  // In a directory that was there before, the store files are this run's to
  // remove only once its store writer holds the lock: until then they may
  // be another's, which the writer refuses to touch.
  void StoreLocked() {
    if (created_) return;
    remove_on_interrupt_.emplace([path = path_] { RemoveUnfinishedStore(path); });  // with the ID index's store in it
  }
  ~OutputGuard() {
    if (!committed_ && created_) {
      std::error_code ignored;
      fs::remove_all(path_, ignored);
    }
  }
  void Commit() {
    committed_ = true;
    remove_on_interrupt_.reset();
  }

 private:
  std::string path_;
  bool created_;
  bool committed_ = false;
  std::optional<RemoveOnInterrupt> remove_on_interrupt_;
};

nlohmann::json CubeJson(const Cube& cube) {
  return {{"origin", cube.origin}, {"size", cube.size}, {"periodic", cube.periodic}};
}

nlohmann::json HeaderJson(const SnapshotHeader& h) {
  return {{"format", h.format},
          {"files", h.files},
          {"time", h.time},
          {"redshift", h.redshift},
          {"box_size", h.box_size},
          {"count_per_type", h.count_per_type},
          {"total_count", h.total_count},
          {"cosmological", h.cosmological},
          {"omega0", h.omega0},
          {"omega_lambda", h.omega_lambda},
          {"hubble_param", h.hubble_param},
          {"extra", h.extra}};
}

// Whether the inner nodes whose points are clusters carry the velocity
// dispersion column: with velocities, when inner nodes are clusters at all
// (a sample's points are particles, whose dispersion is 0).
bool InnerNodesCarryVelocityDispersion(bool has_velocity, CoarsePoints coarse) {
  return has_velocity && coarse == CoarsePoints::kClusters;
}

nlohmann::json AttributeSchema(bool velocity, bool id, bool epoch_links, bool velocity_dispersion, bool shapes) {
  nlohmann::json columns = nlohmann::json::array();
  auto add = [&](ColumnId column, const char* encoding, const char* meaning) {
    columns.push_back({{"id", static_cast<int>(column)}, {"name", ColumnName(column)}, {"encoding", encoding},
                       {"meaning", meaning}});
  };
  add(ColumnId::kPosition, "u16x3 relative to the node cube", "position");
  add(ColumnId::kWeight, "u32 units x f64 unit per block", "mass the point stands for");
  add(ColumnId::kSmoothing, "u16 log2 code relative to the node size", "smoothing length");
  add(ColumnId::kType, "u8", "particle type");
  if (velocity) add(ColumnId::kVelocity, "u16x3 between per-block min and max", "velocity (input units)");
  if (id) add(ColumnId::kId, "u32 offsets from a u64 base per block, or u64", "particle ID");
  if (epoch_links) {
    const char* ranged = "u16x3 between per-block min and max";
    add(ColumnId::kDisplacement, ranged, "offset to the next epoch (minimal image); every epoch but the last");
    if (velocity) add(ColumnId::kNextVelocity, ranged, "velocity at the next epoch; every epoch but the last");
    add(ColumnId::kPrevDisplacement, ranged, "offset to the previous epoch (minimal image); every epoch but the first");
    if (velocity) add(ColumnId::kPrevVelocity, ranged, "velocity at the previous epoch; every epoch but the first");
  }
  if (velocity_dispersion) {
    add(ColumnId::kVelocityDispersion, "u16 between per-block min and max",
        "1-D rms velocity dispersion of the particles a cluster stands for; inner nodes of clusters only");
  }
  if (shapes) {
    add(ColumnId::kShape, "u8x6 covariance over trace / 3 (index/cluster_shape.h)",
        "shape of the blob of the particles a cluster stands for; inner nodes of clusters only");
  }
  return {{"block_format", "index/block_codec.h, docs/FORMAT.md"}, {"columns", columns}};
}

// The link file that the join of epoch e - 1 writes for epoch e (tools/ingest/epoch_join.h).
std::string LinkFilePath(const std::string& temp_dir, std::size_t epoch) {
  return temp_dir + "/links-" + std::to_string(epoch);
}

// Particle IDs must be unique: the ID index and the links between epochs find
// a particle by its ID. `repeats` is how many repeat, 0 when not known.
[[noreturn]] void RefuseDuplicateIds(const SnapshotHeader& header, std::uint64_t id, std::uint64_t repeats) {
  const std::size_t files = header.files.size();
  const std::string where = files > 1 ? " (in the snapshot's " + std::to_string(files) + " files)" : "";
  const std::string count = repeats > 0 ? " (" + std::to_string(repeats) + " repeats in all)" : "";
  throw Error::BadInput(header.files.front(),
                        "ID " + std::to_string(id) + " is given to more than one particle" + where + count +
                            "; particle IDs must be unique, since the ID index and the links between epochs find a "
                            "particle by its ID: ingest with --no-ids to leave the IDs out");
}

bool InsideBox(const ParticleChunk& chunk, const Cube& cube) {
  for (std::size_t i = 0; i < chunk.position.size(); ++i) {
    const double t = chunk.position[i] - cube.origin[i % 3];
    if (!(t >= 0 && t < cube.size)) return false;
  }
  return true;
}

void WrapIntoBox(ParticleChunk& chunk, const Cube& cube) {
  for (std::size_t i = 0; i + 3 <= chunk.position.size(); i += 3) cube.Wrap(&chunk.position[i]);
}

// Holds the epoch of `source` in `resident` mapped from its files
// (ResidentEpoch::Map) when the source's format allows and every value is
// as reading through the source would give it, its IDs counted into
// `census` (fresh) meanwhile. Returns false, nothing held and nothing
// counted, otherwise: the caller then reads through the source, which
// reports or wraps what stopped the mapping.
bool MapResident(const ParticleSource& source, const Cube& cube, const ParticleColumns& columns, unsigned threads,
                 ResidentEpoch& resident, IdCensus& census, Progress& progress) {
  const std::vector<MappableSegment> segments = source.MappableSegments();
  if (segments.empty() || !resident.Map(segments, source.header().files, columns)) return false;
  IdCensus counted = census;
  bool usable = false;
  {
    // The IDs are counted on a thread of their own while all threads check the values.
    std::jthread count_ids;
    if (columns.id) {
      count_ids = std::jthread([&] { resident.VisitIds([&counted](std::span<const std::uint64_t> ids) { counted.Add(ids); }); });
    }
    usable = resident.ValuesAsRead(cube, static_cast<int>(threads), [&progress](std::size_t n) { progress.Add(n); });
  }
  if (!usable) {
    resident = ResidentEpoch();
    progress.Restart();
    return false;
  }
  census = std::move(counted);
  return true;
}

// An epoch's source as ingest reads it, and what screening it found.
struct ScreenedEpoch {
  std::unique_ptr<ParticleSource> source;
  // The bounds of the particles `source` hands out, where the cube is their
  // bounding cube (the survey's pass found them).
  std::optional<Bounds> bounds;
  std::uint64_t read = 0;
  std::uint64_t dropped = 0;
  bool passes = false;  // whether screening read the snapshot
};

// Leaves out what --clip-box leaves out; then, where the cube is the
// particles' bounding cube, looks for outliers (tools/ingest/outliers.h) and
// refuses the epoch for them, or drops them with --drop-outliers. A given
// cube or a periodic box needs no look: particles outside a periodic box are
// the reader's error, and a given cube is the user's choice of resolution.
ScreenedEpoch Screen(std::unique_ptr<ParticleSource> raw, const IngestOptions& options, const std::string& label) {
  ScreenedEpoch out;
  const SnapshotHeader header = raw->header();
  out.read = header.total_count;
  std::optional<PositionSurvey> survey;
  if (options.clip_box) {
    auto clipped = std::make_unique<ClippedSource>(std::move(raw), *options.clip_box, "--clip-box");
    out.dropped += clipped->dropped();
    out.passes = true;
    survey = clipped->survey();
    raw = std::move(clipped);
  }
  if (options.cube || header.box_size > 0) {
    out.source = std::move(raw);
    return out;
  }
  if (!survey) survey = SurveyPositions(*raw, label + ": bounds");
  out.passes = true;
  const OutlierVerdict verdict = JudgeOutliers(*survey);
  if (!verdict.outliers) {
    out.bounds = survey->bounds();
    out.source = std::move(raw);
    return out;
  }
  auto kept = std::make_unique<ClippedSource>(std::move(raw), verdict.bulk, "--drop-outliers");
  if (!options.drop_outliers) RefuseOutliers(header, verdict, kept->dropped(), kept->farthest_dropped());
  out.dropped += kept->dropped();
  out.bounds = kept->survey().bounds();
  out.source = std::move(kept);
  return out;
}

// Wall time of consecutive phases.
class PhaseClock {
 public:
  explicit PhaseClock(EpochReport& report) : report_(report) {}
  void Lap(const char* phase) {
    const auto now = std::chrono::steady_clock::now();
    const double cpu = ProcessCpuSeconds();
    report_.phases.push_back({phase, std::chrono::duration<double>(now - last_).count(), cpu - last_cpu_});
    last_ = now;
    last_cpu_ = cpu;
  }

 private:
  static double ProcessCpuSeconds() {
    timespec t{};
    ::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec) * 1e-9;
  }

  EpochReport& report_;
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
  double last_cpu_ = ProcessCpuSeconds();
};

// Everything one epoch's build shares between the worker threads.
struct EpochBuild {
  const Cube* cube = nullptr;
  const SubtreeOptions* tree = nullptr;
  StoreWriter* store = nullptr;
  // Where the leaves' (ID, leaf) pairs go: the table when the epoch's IDs are
  // unique and compact, else the sorter; both null without IDs.
  DenseIdTable* id_table = nullptr;
  ExternalSorter<IdLeafRecord>* id_pairs = nullptr;
  std::mutex mutex;  // guards report (the store, the table and the sorter take blocks and pairs from several threads)
  EpochReport* report = nullptr;
  Progress* progress = nullptr;

  // Encodes a finished node into `block` (the caller's buffer, reused from
  // node to node) and adds it to the store. `is_leaf` decides whether its
  // IDs go to the ID index.
  void Emit(NodeKey key, const NodePoints& points, bool is_leaf, Bytes& block) {
    EncodeBlock(points, key, *cube, block);
    if (is_leaf && id_table != nullptr) id_table->Add(points.id, key);
    std::vector<IdLeafRecord> pairs;
    if (is_leaf && id_pairs != nullptr) {
      pairs.reserve(points.id.size());
      for (std::uint64_t id : points.id) pairs.push_back({id, key.value()});
    }
    // Neither call holds the other workers up for long: a block's copy into
    // the file and the sorting and writing of a full run of pairs (seconds
    // at 10^8 points) happen outside their locks.
    store->AddBlock(key.value(), block, points.size());
    if (!pairs.empty()) id_pairs->Add(pairs);
    std::lock_guard lock(mutex);
    ++report->nodes;
    report->depth = std::max(report->depth, key.level());
    if (is_leaf) ++report->leaves;
  }
};

// A sink that tells leaves from inner nodes: nodes arrive children first, so
// a node none of whose children has arrived is a leaf.
NodeSink LeafAwareSink(EpochBuild& build, std::unordered_set<std::uint64_t>& has_children, Bytes& block) {
  return [&build, &has_children, &block](NodeKey key, const NodePoints& points) {
    const bool is_leaf = has_children.erase(key.value()) == 0;
    if (key.level() > 0) has_children.insert(key.Parent().value());
    build.Emit(key, points, is_leaf, block);
  };
}

// Builds the chunks' subtrees on `threads` threads and merges the levels
// above them as they complete. Chunks are taken nearly in depth-first order
// (ChunkQueue) and their roots handed to the merger in that order (a root
// that completes early waits for its predecessors), so memory holds a few
// chunk roots plus the merger's open ancestors, never every chunk's sample.
// Returns the root.
// Resident chunks (Chunker::SplitResident) are copied out of `resident` one
// at a time by each worker's gatherer. `chunks_built` is called once every
// chunk is built, before the merger closes the nodes still open above the
// last one: every leaf has been emitted by then.
NodePoints BuildChunks(std::vector<Chunk> chunks, const ResidentEpoch& resident, EpochBuild& build, unsigned threads,
                       const std::function<void()>& chunks_built) {
  Bytes merger_block;  // the merger runs under merge_mutex: one buffer serves it
  TopLevelMerger merger(*build.cube, *build.tree, [&build, &merger_block](NodeKey key, const NodePoints& points) {
    build.Emit(key, points, /*is_leaf=*/false, merger_block);
  });
  std::mutex merge_mutex;  // guards merger, ready, next_to_merge
  std::map<std::size_t, NodePoints> ready;
  std::size_t next_to_merge = 0;
  std::vector<std::uint64_t> point_counts;
  for (const Chunk& chunk : chunks) point_counts.push_back(chunk.point_count);
  ChunkQueue queue(std::move(point_counts), kQueueWindowPerThread * std::size_t{threads});
  std::atomic<bool> failed{false};
  std::exception_ptr error;
  std::mutex error_mutex;
  std::size_t largest_resident = 0;
  for (const Chunk& chunk : chunks) largest_resident = std::max(largest_resident, chunk.resident.size());
  auto work = [&] {
    try {
      Bytes block;  // this worker's encoding buffer
      SubtreeWorkspace workspace;
      ChunkGatherer gatherer(*build.cube, build.tree->max_level);
      gatherer.Reserve(resident, largest_resident);
      for (std::size_t c = queue.Take(); c < chunks.size() && !failed; c = queue.Take()) {
        const std::uint64_t count = chunks[c].point_count;
        std::unordered_set<std::uint64_t> has_children;
        const NodeSink sink = LeafAwareSink(build, has_children, block);
        NodePoints root;
        if (!chunks[c].resident.empty()) {
          root = BuildSubtree(gatherer.Gather(resident, chunks[c]), chunks[c].key, *build.cube, *build.tree, sink,
                              &workspace);
          chunks[c].resident = {};
          chunks[c].resident_lists.reset();  // the last chunk built frees the split's list
        } else {
          root = BuildSubtree(chunks[c].TakePoints(), chunks[c].key, *build.cube, *build.tree, sink, &workspace);
        }
        {
          std::lock_guard lock(merge_mutex);
          ready.emplace(c, std::move(root));
          for (auto it = ready.begin(); it != ready.end() && it->first == next_to_merge; it = ready.erase(it)) {
            merger.Add(chunks[next_to_merge].key, std::move(it->second));
            ++next_to_merge;
          }
        }
        build.progress->Add(count);
      }
    } catch (...) {
      std::lock_guard lock(error_mutex);
      if (!error) error = std::current_exception();
      failed = true;
    }
  };
  std::vector<std::thread> workers;
  for (unsigned t = 1; t < threads; ++t) workers.emplace_back(work);
  work();
  for (auto& worker : workers) worker.join();
  if (error) std::rethrow_exception(error);
  chunks_built();
  return merger.Finish();
}

}  // namespace

std::uint64_t DefaultMemoryBudget() {
  const long pages = ::sysconf(_SC_PHYS_PAGES);
  const long page_size = ::sysconf(_SC_PAGE_SIZE);
  const std::uint64_t physical = pages > 0 && page_size > 0 ? static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page_size) : 0;
  return std::max<std::uint64_t>(physical / 2, std::uint64_t{256} << 20);
}

IngestReport Ingest(const IngestOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  if (options.inputs.empty()) throw Error::InvalidArgument("ingest: no input snapshots given");
  if (options.output.empty()) throw Error::InvalidArgument("ingest: no output store given (-o)");
  if (options.cube) options.cube->Validate();
  if (options.clip_box) options.clip_box->Validate("--clip-box");
  Progress::SetQuiet(options.quiet);

  IngestReport report;
  report.memory_budget = options.memory_budget ? options.memory_budget : DefaultMemoryBudget();
  if (report.memory_budget < (std::uint64_t{32} << 20)) {
    throw Error::InvalidArgument("ingest: a memory budget below 32 MiB is too small to work in");
  }
  const unsigned threads = options.threads ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  const std::uint64_t budget = report.memory_budget;
  // The budget's shares (docs/INGEST.md): the sorted current and next epochs
  // 15 % each, the (ID, leaf) pairs 10 %, chunk buffers 30 %, chunk builds
  // 30 %. Phases overlap only partly, so the sum is a bound, not a forecast.
  const std::uint64_t build_budget_points =
      std::max<std::uint64_t>(budget * 3 / 10 / (threads * kBuildBytesPerPoint), 4 * options.tree.capacity);
  const std::size_t sort_run_records = static_cast<std::size_t>(
      options.sort_run_points ? options.sort_run_points : std::max<std::uint64_t>(budget * 15 / 100 / sizeof(ParticleRecord), 1024));
  // A third of the pairs' share: while one run is sorted (with a scratch as
  // large) the workers fill the next (tools/ingest/external_sorter.h).
  const std::size_t id_run_records = static_cast<std::size_t>(std::max<std::uint64_t>(budget / 30 / sizeof(IdLeafRecord), 1024));
  // Or, for unique IDs in a compact range, the whole share as one table.
  const std::uint64_t id_table_slots = budget / 10 / sizeof(std::uint32_t);

  // Open the first epoch to learn what the series carries.
  std::unique_ptr<ParticleSource> source = OpenSnapshot(options.inputs[0], options.read);
  bool source_smoothed = false;
  const bool has_id = source->header().has_id;
  const bool has_velocity = source->header().has_velocity;
  const bool join_epochs = has_id && options.inputs.size() > 1;

  OutputGuard output_guard(options.output);

  nlohmann::json dataset = {{"generator", "octocosm ingest"},
                            {"capacity", options.tree.capacity},
                            {"max_level", options.tree.max_level},
                            {"coarse", options.tree.coarse == CoarsePoints::kClusters ? "clusters" : "sample"},
                            {"smoothing", {{"rule", options.neighbours > 0 ? "neighbours" : "density grid"},
                                           {"neighbours", std::max(options.neighbours, 0)}}},
                            {"sampler", {{"alpha", options.tree.sampler.alpha},
                                         {"density_grid_bits", options.tree.sampler.density_grid_bits},
                                         {"seed", options.tree.sampler.seed}}},
                            {"has_velocity", has_velocity},
                            {"has_id", has_id},
                            {"has_displacement", join_epochs},
                            {"has_next_velocity", join_epochs && has_velocity},
                            {"has_prev_displacement", join_epochs},
                            {"has_prev_velocity", join_epochs && has_velocity},
                            {"has_velocity_dispersion", InnerNodesCarryVelocityDispersion(has_velocity, options.tree.coarse)},
                            {"has_shape", options.tree.coarse == CoarsePoints::kClusters},
                            {"id_index", has_id ? "ids" : ""},
                            {"epochs", nlohmann::json::array()}};
  StoreWriterOptions store_options;
  store_options.page_size = options.page_size;
  StoreWriter store(options.output, dataset,
                    AttributeSchema(has_velocity, has_id, join_epochs,
                                    InnerNodesCarryVelocityDispersion(has_velocity, options.tree.coarse),
                                    options.tree.coarse == CoarsePoints::kClusters),
                    store_options);
  std::unique_ptr<StoreWriter> id_store;
  const std::uint32_t id_index_page_size = std::max(options.page_size, kIdIndexMinPageSize);
  if (has_id) {
    StoreWriterOptions id_store_options = store_options;
    id_store_options.page_size = id_index_page_size;
    id_store = std::make_unique<StoreWriter>((fs::path(options.output) / "ids").string(),
                                             nlohmann::json{{"id_index_of", ".."}, {"layout", "index/id_index.h"}},
                                             nlohmann::json::object(), id_store_options);
  }
  output_guard.StoreLocked();
  // Inside the output by default: where this run may surely write, and where
  // a rerun finds it if a kill leaves it behind (TempDirectory). Made after
  // the store writers, which clear away an abandoned store first.
  TempDirectory temp(options.temp_dir.empty() ? options.output : options.temp_dir, "octocosm-ingest");

  // The leaves' smoothing lengths from neighbours (or the snapshot's own),
  // computed before anything else reads the epoch, in the whole budget (the
  // pass is done with its memory before the epoch's build takes it, but for
  // the lengths themselves: 4 bytes a particle, or a mapped file).
  auto smooth = [&](std::unique_ptr<ParticleSource> raw) -> std::unique_ptr<ParticleSource> {
    if (options.neighbours <= 0) return raw;
    SmoothingPassOptions pass;
    pass.neighbours = options.neighbours;
    // Neighbours across the faces where ingest wraps into a periodic box.
    pass.box_size = options.cube ? 0.0 : raw->header().box_size;
    pass.memory_budget = budget;
    pass.temp_dir = temp.path();
    pass.threads = threads;
    pass.quiet = options.quiet;
    std::shared_ptr<const SmoothingLengthTable> table = ComputeSmoothingLengths(*raw, pass);
    return WithSmoothingLengths(std::move(raw), std::move(table));
  };

  // Each epoch screened (Screen) before anything else reads it; the
  // smoothing pass then sees only the particles kept.
  std::vector<ScreenedEpoch> screened(options.inputs.size());
  auto prepare = [&](std::unique_ptr<ParticleSource> raw, std::size_t e, PhaseClock* clock) {
    ScreenedEpoch s = Screen(std::move(raw), options, "epoch " + std::to_string(e));
    if (clock != nullptr && s.passes) clock->Lap("bounds");
    std::unique_ptr<ParticleSource> prepared = smooth(std::move(s.source));
    screened[e] = std::move(s);
    return prepared;
  };

  std::unique_ptr<SortedEpoch> sorted_current, sorted_next;
  std::uint64_t missing_in_prev = 0;  // of the epoch to come, counted by the join before it
  auto sort_epoch = [&](ParticleSource& s, std::size_t e) {
    Progress progress("epoch " + std::to_string(e) + ": sort by ID", s.header().total_count, "points");
    auto sorted = std::make_unique<SortedEpoch>(s, temp.path() + "/sorted-" + std::to_string(e), sort_run_records,
                                                [&](std::uint64_t n) { progress.Add(n); });
    if (sorted->duplicate_ids() > 0) RefuseDuplicateIds(s.header(), sorted->first_duplicate_id(), sorted->duplicate_ids());
    progress.Finish();
    return sorted;
  };

  for (std::size_t e = 0; e < options.inputs.size(); ++e) {
    if (!source) source = OpenSnapshot(options.inputs[e], options.read);
    EpochReport epoch_report;
    PhaseClock clock(epoch_report);
    if (!source_smoothed) {
      source = prepare(std::move(source), e, &clock);
      if (options.neighbours > 0) clock.Lap("smoothing");
    }
    const SnapshotHeader header = source->header();
    if (header.has_id != has_id || header.has_velocity != has_velocity) {
      throw Error::BadInput(header.files.front(), "this epoch " + std::string(header.has_id ? "has" : "lacks") +
                                                      " IDs / velocities unlike epoch 0; all epochs of a series must carry the same columns");
    }
    const std::string label = "epoch " + std::to_string(e);

    // 1. sort (series with IDs) or bounds.
    std::unique_ptr<ParticleSource> next_source;
    Bounds bounds;
    if (join_epochs) {
      if (!sorted_current) sorted_current = sort_epoch(*source, e);
      if (e + 1 < options.inputs.size()) {
        if (options.neighbours > 0) clock.Lap("sort");
        next_source = prepare(OpenSnapshot(options.inputs[e + 1], options.read), e + 1, nullptr);
        if (options.neighbours > 0) clock.Lap("next smoothing");
        sorted_next = sort_epoch(*next_source, e + 1);
      }
      bounds = sorted_current->bounds();
      epoch_report.duplicate_ids = sorted_current->duplicate_ids();
    } else if (screened[e].bounds) {
      bounds = *screened[e].bounds;  // the survey's, before the smoothing pass
    }

    if (join_epochs) clock.Lap(next_source && options.neighbours > 0 ? "next sort" : "sort");
    Cube cube;
    if (options.cube) {
      cube = *options.cube;
    } else if (header.box_size > 0) {
      cube = {{0, 0, 0}, header.box_size, true};
    } else if (!bounds.empty()) {
      cube = Cube::FromBounds(bounds.lo, bounds.hi);
    }

    // The epoch's points as a repeatable pass, wrapped into a periodic box.
    const SortedEpoch* next_sorted = sorted_next.get();
    const double box = cube.periodic ? cube.size : 0.0;
    const std::string links_from_previous = join_epochs && e > 0 ? LinkFilePath(temp.path(), e) : "";
    const std::string links_to_next = next_sorted != nullptr ? LinkFilePath(temp.path(), e + 1) : "";
    JoinStats join_stats;
    PointPass pass = [&](const std::function<void(const ParticleChunk&)>& consume) {
      auto forward = [&](const ParticleChunk& chunk) {
        if (!cube.periodic || InsideBox(chunk, cube)) return consume(chunk);
        ParticleChunk wrapped = chunk;
        WrapIntoBox(wrapped, cube);
        consume(wrapped);
      };
      if (join_epochs) {
        join_stats = JoinedPass(*sorted_current, next_sorted, links_from_previous, links_to_next, box,
                                options.read.chunk_particles, forward);
      } else {
        source->Rewind();
        ParticleChunk chunk;
        while (source->Next(chunk)) forward(chunk);
      }
    };

    // 2. chunk. Chunks small enough for memory and the caches, and numerous
    // enough (four per thread) that every core has work until the end.
    const std::uint64_t expected = join_epochs ? bounds.count : header.total_count;
    const std::uint64_t max_chunk =
        options.max_chunk_points
            ? options.max_chunk_points
            : std::min(build_budget_points,
                       std::max<std::uint64_t>(std::min(expected / (4 * threads), kMaxChunkPoints), 4 * options.tree.capacity));
    report.max_chunk_points = std::max(report.max_chunk_points, max_chunk);
    ChunkerOptions chunker_options;
    chunker_options.max_chunk_points = max_chunk;
    chunker_options.split_levels = SplitLevelsFor(expected, max_chunk);
    chunker_options.max_level = options.tree.max_level;
    chunker_options.leaf_capacity = options.tree.capacity;
    // Capped: measured on this project's machines, buffering gigabytes of
    // points costs more in first-touch page faults than spilling them to
    // temporary files that stay in the OS page cache (docs/BENCHMARKS.md).
    chunker_options.memory_bytes = static_cast<std::size_t>(std::min<std::uint64_t>(budget * 3 / 10, kMaxChunkBufferBytes));
    chunker_options.temp_dir = temp.path();
    chunker_options.threads = static_cast<int>(threads);
    chunker_options.columns.id = has_id;
    // Epoch by epoch: a series may give smoothing lengths in some snapshots only.
    chunker_options.columns.smoothing = header.has_smoothing;
    chunker_options.columns.vector(VectorColumn::kVelocity) = has_velocity;
    chunker_options.columns.vector(VectorColumn::kDisplacement) = next_sorted != nullptr;
    chunker_options.columns.vector(VectorColumn::kNextVelocity) = next_sorted != nullptr && has_velocity;
    chunker_options.columns.vector(VectorColumn::kPrevDisplacement) = !links_from_previous.empty();
    chunker_options.columns.vector(VectorColumn::kPrevVelocity) = !links_from_previous.empty() && has_velocity;
    // A point set that fits in its share of the budget whole (the chunk
    // buffers' share, and the sorted epochs' too when there are none) is read
    // into memory once and chunked in place (Chunker::SplitResident). The
    // split's own memory must fit the builds' and the ID pairs' shares: its
    // cells go before the builds start, its index lists as their chunks are
    // built.
    const std::uint64_t resident_share = budget * (join_epochs ? 3 : 6) / 10;
    const bool resident = !options.stream_chunks && expected < UINT32_MAX &&
                          expected * chunker_options.columns.BytesPerPoint() <= resident_share &&
                          expected * Chunker::kResidentScratchBytesPerPoint <= budget * 4 / 10;
    ResidentEpoch resident_points;
    std::vector<Chunk> chunks;
    IdCensus id_census(id_table_slots);
    {
      Progress progress(label + ": read + chunk", expected, "points");
      PointPass counted = [&](const std::function<void(const ParticleChunk&)>& consume) {
        pass([&](const ParticleChunk& chunk) {
          consume(chunk);
          id_census.Add(chunk.id);
          progress.Add(chunk.size());
        });
      };
      Chunker chunker(cube, chunker_options);
      if (resident) {
        const bool mapped = !join_epochs && MapResident(*source, cube, chunker_options.columns, threads, resident_points,
                                                        id_census, progress);
        if (!mapped) resident_points.Read(counted, expected, chunker_options.columns);
        chunks = chunker.SplitTail(chunker.SplitResident(NodeKey::Root(), resident_points), resident_points,
                                   kQueueWindowPerThread * threads, max_chunk / kTailChunkFraction);
      } else {
        chunks = chunker.Split(NodeKey::Root(), counted);
      }
      epoch_report.spilled_points = chunker.spilled_points();
      epoch_report.resident = resident;
      epoch_report.mapped = resident_points.mapped();
    }
    clock.Lap("read+chunk");
    if (has_id && id_census.repeated_id()) RefuseDuplicateIds(header, *id_census.repeated_id(), 0);
    for (const Chunk& c : chunks) epoch_report.points += c.point_count;
    epoch_report.read_points = screened[e].read;
    epoch_report.dropped_points = screened[e].dropped;
    epoch_report.chunks = chunks.size();
    if (!links_from_previous.empty()) std::remove(links_from_previous.c_str());
    epoch_report.missing_in_next = join_stats.missing_in_next;
    epoch_report.missing_in_prev = missing_in_prev;
    missing_in_prev = join_stats.new_in_next;
    if (next_sorted != nullptr) {
      const VelocityScaleFit& fit = join_stats.fit;
      // A Hermite curve strays from its chord by at most 4/27 of each
      // tangent (the peak of the basis functions h10 and h11).
      const double excursion = join_stats.max_displacement +
                               4.0 / 27.0 * std::fabs(fit.velocity_scale()) * join_stats.max_speed_sum;
      epoch_report.to_next = EpochLink{fit.velocity_scale(), fit.fit_residual(), fit.least_squares_scale(),
                                       fit.inlier_fraction(), join_stats.matched, excursion};
    }

    // 3. build, 4. top levels.
    store.BeginEpoch(header.time, header.redshift);
    std::unique_ptr<DenseIdTable> id_table;
    std::unique_ptr<ExternalSorter<IdLeafRecord>> id_pairs;
    if (has_id && id_census.dense() && id_census.count() == epoch_report.points) {
      id_table = std::make_unique<DenseIdTable>(id_census.first(), id_census.span());
    } else if (has_id) {
      epoch_report.ids_sorted = true;
      id_pairs = std::make_unique<ExternalSorter<IdLeafRecord>>(temp.path() + "/ids-" + std::to_string(e), id_run_records);
      id_pairs->Reserve(static_cast<std::size_t>(epoch_report.points));
    }
    EpochBuild build;
    build.cube = &cube;
    build.tree = &options.tree;
    build.store = &store;
    build.id_table = id_table.get();
    build.id_pairs = id_pairs.get();
    build.report = &epoch_report;
    // 5. ID index. It needs only the leaves, so it is written on a thread of
    // its own from when the last chunk is built, while the merger closes the
    // nodes above it, and while the epoch's page file is finished (mostly
    // waiting for fsync). The store and the ID store share no state.
    auto write_id_index = [&] {
      if (id_pairs) id_pairs->Finish();
      id_store->BeginEpoch(header.time, header.redshift);
      IdIndexEpochWriter ids(*id_store, id_index_page_size);
      if (id_table) {
        if (id_table->narrow()) {
          ids.AddTable(id_table->first(), id_table->narrow_slots(), id_table->leaves());
        } else {
          ids.AddTable(id_table->first(), id_table->wide_slots(), id_table->leaves());
        }
      } else {
        auto reader = id_pairs->Open();
        IdLeafRecord r{};
        for (std::uint64_t n = 0, previous = 0; reader.Next(r); ++n, previous = r.key) {
          // What the census could not see: a repeat among IDs too far apart for its table.
          if (n > 0 && r.key == previous) RefuseDuplicateIds(header, r.key, 0);
          ids.Add(r.key, NodeKey::FromValue(r.leaf));
        }
      }
      ids.Finish();
      id_store->EndEpoch();
    };
    std::future<void> id_index_written;
    {
      Progress progress(label + ": build", epoch_report.points, "points");
      build.progress = &progress;
      const NodePoints root = BuildChunks(std::move(chunks), resident_points, build, threads, [&] {
        if (has_id) id_index_written = std::async(std::launch::async, write_id_index);
      });
      resident_points = ResidentEpoch();
      for (double w : root.weight) epoch_report.mass += w;
      progress.Finish();
    }
    clock.Lap("build");
    std::future<void> epoch_written = std::async(std::launch::async, [&store] { store.EndEpoch(); });
    if (has_id) {
      id_index_written.get();
      clock.Lap("ids");
    }
    epoch_written.get();
    clock.Lap("write");

    nlohmann::json epoch_json = {{"epoch", e},
                                 {"input", HeaderJson(header)},
                                 {"cube", CubeJson(cube)},
                                 {"points", epoch_report.points},
                                 {"mass", epoch_report.mass},
                                 {"nodes", epoch_report.nodes},
                                 {"leaves", epoch_report.leaves},
                                 {"depth", epoch_report.depth},
                                 {"missing_in_next", epoch_report.missing_in_next},
                                 {"missing_in_prev", epoch_report.missing_in_prev},
                                 {"duplicate_ids", epoch_report.duplicate_ids}};
    if (epoch_report.to_next) {
      const EpochLink& link = *epoch_report.to_next;
      epoch_json["to_next"] = {{"velocity_scale", link.velocity_scale},
                               {"fit_residual", link.fit_residual},
                               {"least_squares_scale", link.least_squares_scale},
                               {"inlier_fraction", link.inlier_fraction},
                               {"matched", link.matched},
                               {"max_excursion", link.max_excursion}};
    }
    dataset["epochs"].push_back(std::move(epoch_json));
    report.input_points += epoch_report.points;
    report.read_points += epoch_report.read_points;
    report.dropped_points += epoch_report.dropped_points;
    report.epochs.push_back(epoch_report);

    // The next epoch reuses what this one read ahead.
    sorted_current = std::move(sorted_next);
    source = std::move(next_source);
    source_smoothed = source != nullptr;
  }

  if (id_store) id_store->Finish();
  store.SetDataset(dataset);
  store.Finish();
  output_guard.Commit();
  report.store_bytes = store.bytes_written() + (id_store ? id_store->bytes_written() : 0);
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

}  // namespace octocosm
