#include "ingest/ingest.h"

#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <thread>
#include <unordered_set>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "base/interrupt_cleanup.h"
#include "base/mutex.h"
#include "base/parallel_for.h"
#include "base/progress.h"
#include "base/temp_directory.h"
#include "index/block_codec.h"
#include "index/dataset_manifest.h"
#include "index/id_index.h"
#include "ingest/chunk_gatherer.h"
#include "ingest/chunk_queue.h"
#include "ingest/chunker.h"
#include "ingest/clipped_source.h"
#include "ingest/dense_id_table.h"
#include "ingest/epoch_domains.h"
#include "ingest/epoch_join.h"
#include "ingest/external_sorter.h"
#include "ingest/outliers.h"
#include "ingest/rank_group.h"
#include "ingest/rank_messages.h"
#include "ingest/resident_epoch.h"
#include "ingest/smoothing_pass.h"
#include "ingest/spread_id_index.h"
#include "storage/http_file.h"
#include "storage/page_file_reader.h"
#include "storage/store_writer.h"

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
// caches. At 10^7 points the ingest took 1.23-1.45 s with them against
// 1.51-1.57 s with chunks of 1.25 million points, and about 175 MiB less
// peak RSS; at 10^8 the size matters little (docs/BENCHMARKS.md).
constexpr std::uint64_t kMaxChunkPoints = std::uint64_t{1} << 18;
// The build threads take chunks from a window of this many per thread
// (ingest/chunk_queue.h), so the last ones built are among the last
// that many; those are cut to at most an eighth of the largest chunk
// (Chunker::SplitTail), a few milliseconds' work each.
constexpr std::size_t kQueueWindowPerThread = 4;
constexpr std::uint64_t kTailChunkFraction = 8;

// Removes the output directory on failure, and when a signal ends the
// program (base/interrupt_cleanup.h), but only if this run created it; in
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
    add(ColumnId::kChildCluster, "u16 (u32 past 65536 points) per point of the children, u64 count",
        "the cluster of this node that holds each of its children's points; inner nodes of clusters only");
    add(ColumnId::kRefineBound, "f32x3",
        "radius of the sphere holding the clusters below, bounds of their mass x blob variance and of their mass; "
        "inner nodes of clusters only");
  }
  return {{"block_format", "index/block_codec.h, docs/FORMAT.md"}, {"columns", columns}};
}

// The link file that the join of epoch e - 1 writes for epoch e (ingest/epoch_join.h).
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
// particles' bounding cube, looks for outliers (ingest/outliers.h) and
// refuses the epoch for them, or drops them with --drop-outliers. A given
// cube or a periodic box needs no look: particles outside a periodic box are
// the reader's error, and a given cube is the user's choice of resolution.
// With a group (an epoch spread over ranks), each rank reads its share of
// the batches for these passes and every rank comes to the same verdict.
ScreenedEpoch Screen(std::unique_ptr<ParticleSource> raw, const IngestOptions& options, const std::string& label,
                     RankGroup* group = nullptr) {
  ScreenedEpoch out;
  const SnapshotHeader header = raw->header();
  out.read = header.total_count;
  std::optional<PositionSurvey> survey;
  if (options.clip_box) {
    auto clipped = std::make_unique<ClippedSource>(std::move(raw), *options.clip_box, "--clip-box", group);
    out.dropped += clipped->dropped();
    out.passes = true;
    survey = clipped->survey();
    raw = std::move(clipped);
  }
  if (options.cube || header.box_size > 0) {
    out.source = std::move(raw);
    return out;
  }
  if (!survey) survey = SurveyPositions(*raw, label + ": bounds", group);
  out.passes = true;
  const OutlierVerdict verdict = JudgeOutliers(*survey);
  if (!verdict.outliers) {
    out.bounds = survey->bounds();
    out.source = std::move(raw);
    return out;
  }
  auto kept = std::make_unique<ClippedSource>(std::move(raw), verdict.bulk, "--drop-outliers", group);
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

// Messages kept in a file until they are sent: a rank's domain roots, each
// up to a node's capacity of points, which it may hold dozens of.
class MessageFile {
 public:
  explicit MessageFile(std::string path) : path_(std::move(path)), file_(std::fopen(path_.c_str(), "w+b"), &std::fclose) {
    if (!file_) throw Error::Io(path_, std::string("cannot create: ") + std::strerror(errno));
    std::remove(path_.c_str());  // open still; gone whatever happens to the process
  }
  void Add(const Bytes& message) {
    const std::uint64_t size = message.size();
    if (std::fwrite(&size, sizeof size, 1, file_.get()) != 1 ||
        (size > 0 && std::fwrite(message.data(), 1, message.size(), file_.get()) != message.size())) {
      throw Error::Io(path_, std::string("cannot write: ") + std::strerror(errno));
    }
    ++count_;
  }
  std::uint64_t count() const { return count_; }
  // Every message, in the order added.
  void ForEach(const std::function<void(const Bytes&)>& visit) {
    if (std::fflush(file_.get()) != 0 || std::fseek(file_.get(), 0, SEEK_SET) != 0) {
      throw Error::Io(path_, std::string("cannot read back: ") + std::strerror(errno));
    }
    Bytes message;
    for (std::uint64_t k = 0; k < count_; ++k) {
      std::uint64_t size = 0;
      if (std::fread(&size, sizeof size, 1, file_.get()) != 1) throw Error::Io(path_, "cut short");
      message.resize(static_cast<std::size_t>(size));
      if (size > 0 && std::fread(message.data(), 1, message.size(), file_.get()) != message.size()) {
        throw Error::Io(path_, "cut short");
      }
      visit(message);
    }
  }

 private:
  std::string path_;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file_;
  std::uint64_t count_ = 0;
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
  const SnapshotHeader* header = nullptr;  // the epoch's files, named when its IDs repeat
  // The store, the table and the sorter take blocks and pairs from several
  // threads; the report takes this lock.
  Mutex mutex;
  EpochReport* report PT_GUARDED_BY(mutex) = nullptr;
  Progress* progress = nullptr;
  // A spread epoch (IngestSpreadInto): the domain being built, whose root
  // node is copied into `domain_root`. The nodes above it hold other ranks'
  // points too, so they are left out here. Invalid for a whole epoch.
  NodeKey domain;
  NodePoints* domain_root = nullptr;
  LeafIdsFile* leaf_ids = nullptr;  // where a spread epoch's leaves' IDs go

  // Encodes a finished node into `block` (the caller's buffer, reused from
  // node to node) and adds it to the store. `is_leaf` decides whether its
  // IDs go to the ID index.
  void Emit(NodeKey key, const NodePoints& points, bool is_leaf, Bytes& block) {
    if (domain.IsValid()) {
      if (!domain.IsAncestorOrSelf(key)) return;
      // Once per domain; read by the thread that waits for the build.
      if (key == domain) *domain_root = points;
    }
    EncodeBlock(points, key, *cube, block);
    if (is_leaf && id_table != nullptr) RecordLeafIds(points.id, key);
    if (is_leaf && leaf_ids != nullptr) leaf_ids->Add(key, points.id);
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
    MutexLock lock(mutex);
    ++report->nodes;
    report->depth = std::max(report->depth, key.level());
    if (is_leaf) ++report->leaves;
  }

  // Adds a leaf's IDs to the table, refusing the snapshot for an ID it
  // gives twice.
  void RecordLeafIds(std::span<const std::uint64_t> ids, NodeKey leaf) const {
    if (const std::optional<std::uint64_t> repeated = id_table->Add(ids, leaf)) {
      RefuseDuplicateIds(*header, *repeated, 0);
    }
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
  Mutex merge_mutex;  // guards merger, ready, next_to_merge
  std::map<std::size_t, NodePoints> ready;
  std::size_t next_to_merge = 0;
  std::vector<std::uint64_t> point_counts;
  for (const Chunk& chunk : chunks) point_counts.push_back(chunk.point_count);
  ChunkQueue queue(std::move(point_counts), kQueueWindowPerThread * std::size_t{threads});
  std::size_t largest_resident = 0;
  for (const Chunk& chunk : chunks) largest_resident = std::max(largest_resident, chunk.resident.size());
  RunWorkers(static_cast<int>(threads), [&](int, const std::atomic<bool>& stop) {
    Bytes block;  // this worker's encoding buffer
    SubtreeWorkspace workspace;
    ChunkGatherer gatherer(*build.cube, build.tree->max_level);
    gatherer.Reserve(resident, largest_resident);
    for (std::size_t c = queue.Take(); c < chunks.size() && !stop; c = queue.Take()) {
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
        MutexLock lock(merge_mutex);
        ready.emplace(c, std::move(root));
        for (auto it = ready.begin(); it != ready.end() && it->first == next_to_merge; it = ready.erase(it)) {
          merger.Add(chunks[next_to_merge].key, std::move(it->second));
          ++next_to_merge;
        }
      }
      build.progress->Add(count);
    }
  });
  chunks_built();
  return merger.Finish();
}

// The memory budget's shares (docs/INGEST.md): the sorted current and next
// epochs 15 % each, the (ID, leaf) pairs 10 %, chunk buffers 30 %, chunk
// builds 30 %. Phases overlap only partly, so the sum is a bound, not a
// forecast.
struct MemoryShares {
  MemoryShares(std::uint64_t total, unsigned threads, const IngestOptions& options)
      : budget(total),
        build_points(std::max<std::uint64_t>(total * 3 / 10 / (threads * kBuildBytesPerPoint), 4 * options.tree.capacity)),
        sort_run_records(static_cast<std::size_t>(
            options.sort_run_points ? options.sort_run_points
                                    : std::max<std::uint64_t>(total * 15 / 100 / sizeof(ParticleRecord), 1024))),
        id_run_records(static_cast<std::size_t>(std::max<std::uint64_t>(total / 30 / sizeof(IdLeafRecord), 1024))),
        id_table_slots(total / 10 / sizeof(std::uint32_t)),
        chunk_buffer_bytes(static_cast<std::size_t>(std::min<std::uint64_t>(total * 3 / 10, kMaxChunkBufferBytes))) {}

  std::uint64_t budget;
  std::uint64_t build_points;    // the builds' 30 %, a thread's share in points
  std::size_t sort_run_records;  // a sorted epoch's 15 %
  // A third of the pairs' 10 %: while one run is sorted (with a scratch as
  // large) the workers fill the next (ingest/external_sorter.h).
  std::size_t id_run_records;
  // Or, for unique IDs in a compact range, the pairs' whole share as one table.
  std::uint64_t id_table_slots;
  // The chunk buffers' 30 %, capped: measured on this project's machines,
  // buffering gigabytes of points costs more in first-touch page faults
  // than spilling them to temporary files that stay in the OS page cache
  // (docs/BENCHMARKS.md).
  std::size_t chunk_buffer_bytes;
  // A point set that fits whole in the chunk buffers' share (and the sorted
  // epochs' too when there are none) is held in memory and chunked in place
  // (Chunker::SplitResident); the split's own memory must fit the builds'
  // and the ID pairs' shares (40 %): its cells go before the builds start,
  // its index lists as their chunks are built.
  std::uint64_t ResidentBytes(bool sorted_epochs) const { return budget * (sorted_epochs ? 3 : 6) / 10; }
  std::uint64_t ResidentScratchBytes() const { return budget * 4 / 10; }
};

// One epoch's particles as the steps after the first see them: a pass that
// can be repeated, wrapped into a periodic box, joined to the next epoch in
// a series with IDs.
struct EpochPoints {
  ParticleSource* source = nullptr;
  const SortedEpoch* current = nullptr;  // a series with IDs: this epoch and the next, sorted
  const SortedEpoch* next = nullptr;
  Cube cube;
  std::string links_from_previous, links_to_next;  // the join's files (ingest/epoch_join.h)
  std::size_t chunk_particles = 0;
  JoinStats join_stats;  // of the latest joined pass

  // Every `every`-th batch from the `first`-th, the others skipped (read
  // only where the source cannot seek); returns how many batches the epoch
  // has. Not for a joined pass, which has no batches of the source's.
  std::uint64_t PassShare(std::uint64_t every, std::uint64_t first, const std::function<void(const ParticleChunk&)>& consume) {
    ParticleChunk chunk;
    return ReadShare(*source, every, first, chunk, [&](ParticleChunk& batch, std::uint64_t) {
      if (cube.periodic && !InsideBox(batch, cube)) WrapIntoBox(batch, cube);
      consume(batch);
    });
  }

  void Pass(const std::function<void(const ParticleChunk&)>& consume) {
    auto forward = [&](const ParticleChunk& chunk) {
      if (!cube.periodic || InsideBox(chunk, cube)) return consume(chunk);
      ParticleChunk wrapped = chunk;
      WrapIntoBox(wrapped, cube);
      consume(wrapped);
    };
    if (current != nullptr) {
      join_stats = JoinedPass(*current, next, links_from_previous, links_to_next, cube.periodic ? cube.size : 0.0,
                              chunk_particles, forward);
    } else {
      source->Rewind();
      ParticleChunk chunk;
      while (source->Next(chunk)) forward(chunk);
    }
  }
};

// An epoch cut into chunks, with what the cutting counted.
struct ChunkedEpoch {
  std::vector<Chunk> chunks;
  ResidentEpoch resident;  // the points, when held in memory whole
  IdCensus ids;
};

// A whole ingest: the store being written and what carries from one epoch
// to the next. Ingest() below reads as its steps.
class IngestRun {
 public:
  // The whole series into options.output, or a share of it into a part's
  // directory (IngestShareInto).
  explicit IngestRun(const IngestOptions& options, const IngestShare* share = nullptr,
                     const std::string& part_directory = "", RankGroup* group = nullptr);
  void IngestEpoch(std::size_t e);
  // A rank other than 0 of a spread epoch, once its part is finished: tells
  // rank 0 where its blocks and its share of the ID index are and what it
  // built.
  void SendSpreadSummary(const IngestPart& part);
  // The same rank next: copies its blocks (and its ID index's) into the
  // store's page files where rank 0 made room for them, and tells rank 0
  // when they are there (or why not).
  void CopyBlocksForRankZero(const IngestPart& part);
  IngestReport Finish();
  IngestPart FinishPart();

 private:
  std::unique_ptr<ParticleSource> Smooth(std::unique_ptr<ParticleSource> raw);
  std::unique_ptr<ParticleSource> Prepare(std::unique_ptr<ParticleSource> raw, std::size_t e, PhaseClock* clock);
  std::unique_ptr<SortedEpoch> SortEpoch(ParticleSource& source, std::size_t e);
  Bounds SortOrBound(std::size_t e, PhaseClock& clock, EpochReport& epoch_report);
  void LinkFromPrevious(std::size_t e);
  Cube ChooseCube(const SnapshotHeader& header, const Bounds& bounds) const;
  ChunkerOptions ChunkerOptionsFor(std::uint64_t expected, const ParticleColumns& columns);
  ChunkedEpoch ChunkEpoch(const std::string& label, const SnapshotHeader& header, std::uint64_t expected,
                          EpochPoints& points, EpochReport& epoch_report);
  void RecordLinks(const EpochPoints& points, EpochReport& epoch_report);
  void BuildAndWrite(std::size_t e, const SnapshotHeader& header, const Cube& cube, ChunkedEpoch& chunked,
                     EpochReport& epoch_report, PhaseClock& clock);
  void WriteIdIndex(const SnapshotHeader& header, DenseIdTable* id_table, ExternalSorter<IdLeafRecord>* id_pairs);
  // One epoch over the ranks of group_ (IngestSpreadInto), in its steps.
  void IngestSpreadEpoch(std::size_t e);
  struct SpreadCensus;
  SpreadCensus CountForDomains(const std::string& label, EpochPoints& points, const PointPass& my_batches,
                               std::uint64_t& batches);
  struct DomainFile {
    std::string path;
    std::uint64_t points = 0;
  };
  std::vector<DomainFile> ExchangeToDomains(const std::string& label, EpochPoints& points, const PointPass& my_batches,
                                            std::uint64_t batches, const EpochDomains& domains,
                                            const ParticleColumns& columns);
  void BuildDomains(const std::string& label, const Cube& cube, const std::vector<NodeKey>& mine,
                    const std::vector<DomainFile>& files, const ParticleColumns& columns, EpochBuild& build,
                    EpochReport& epoch_report, TopLevelMerger* top);
  void MergeOtherRanksRoots(const std::string& label, EpochReport& epoch_report, TopLevelMerger& top,
                            PhaseClock& clock);
  void WriteIdIndexShare(const SnapshotHeader& header, const SpreadCensus& census, LeafIdsFile& leaf_ids,
                         EpochReport& epoch_report);
  void GatherOtherRanks(const std::string& label, EpochReport& epoch_report);

  const IngestOptions& options_;
  const std::string output_;
  const std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  const std::size_t first_epoch_;
  IngestReport report_;
  unsigned threads_;
  MemoryShares shares_;
  std::unique_ptr<ParticleSource> source_;  // the epoch to ingest next, when opened ahead
  bool has_id_, has_velocity_, join_epochs_;
  DatasetManifest manifest_;
  // Declared in the order they must be made; destroyed the other way round.
  OutputGuard output_guard_;
  StoreWriter store_;
  std::unique_ptr<StoreWriter> id_store_;
  std::uint32_t id_index_page_size_;
  std::optional<TempDirectory> temp_;
  std::vector<ScreenedEpoch> screened_;
  bool source_smoothed_ = false;
  std::unique_ptr<SortedEpoch> sorted_current_, sorted_next_;
  std::unique_ptr<ParticleSource> next_source_;
  std::uint64_t missing_in_prev_ = 0;  // of the epoch to come, counted by the join before it
  RankGroup* group_ = nullptr;         // the ranks an epoch is spread over, or null
  EpochReport spread_report_;          // what this rank built of a spread epoch
};

std::unique_ptr<StoreWriter> MakeIdStoreWriter(const std::string& output, const StoreWriterOptions& options) {
  return std::make_unique<StoreWriter>((fs::path(output) / "ids").string(),
                                       nlohmann::json{{"id_index_of", ".."}, {"layout", "index/id_index.h"}},
                                       nlohmann::json::object(), options);
}

IngestReport StartReport(const IngestOptions& options) {
  if (options.inputs.empty()) throw Error::InvalidArgument("ingest: no input snapshots given");
  if (options.output.empty()) throw Error::InvalidArgument("ingest: no output store given (-o)");
  if (IsHttpUrl(options.output)) {
    throw Error::InvalidArgument("ingest: -o " + options.output +
                                 ": a store is written to a local directory; serve that directory over HTTP "
                                 "(docs/REMOTE.md)");
  }
  if (options.cube) options.cube->Validate();
  if (options.clip_box) options.clip_box->Validate("--clip-box");
  Progress::SetQuiet(options.quiet);
  IngestReport report;
  report.memory_budget = options.memory_budget ? options.memory_budget : DefaultMemoryBudget();
  if (report.memory_budget < (std::uint64_t{32} << 20)) {
    throw Error::InvalidArgument("ingest: a memory budget below 32 MiB is too small to work in");
  }
  return report;
}

DatasetManifest ManifestFor(const IngestOptions& options, bool has_id, bool has_velocity, bool join_epochs) {
  DatasetManifest m;
  m.capacity = options.tree.capacity;
  m.max_level = options.tree.max_level;
  m.coarse = options.tree.coarse == CoarsePoints::kClusters ? "clusters" : "sample";
  m.smoothing_rule = options.neighbours > 0 ? "neighbours" : "density grid";
  m.neighbours = std::max(options.neighbours, 0);
  m.sampler = options.tree.sampler;
  m.has_velocity = has_velocity;
  m.has_id = has_id;
  m.has_displacement = join_epochs;
  m.has_next_velocity = join_epochs && has_velocity;
  m.has_prev_displacement = join_epochs;
  m.has_prev_velocity = join_epochs && has_velocity;
  m.has_velocity_dispersion = InnerNodesCarryVelocityDispersion(has_velocity, options.tree.coarse);
  m.has_shape = options.tree.coarse == CoarsePoints::kClusters;
  m.has_cluster_links = m.has_shape;
  m.id_index = has_id ? "ids" : "";
  return m;
}

StoreWriterOptions StoreOptions(const IngestOptions& options, const IngestShare* share, bool id_index) {
  StoreWriterOptions store_options;
  store_options.page_size = id_index ? std::max(options.page_size, kIdIndexMinPageSize) : options.page_size;
  if (share != nullptr) {
    store_options.store_id = id_index ? share->id_store_id : share->store_id;
    store_options.first_epoch = static_cast<std::uint32_t>(share->first_epoch);
  }
  return store_options;
}

IngestRun::IngestRun(const IngestOptions& options, const IngestShare* share, const std::string& part_directory,
                     RankGroup* group)
    : options_(options),
      output_(share != nullptr ? part_directory : options.output),
      first_epoch_(share != nullptr ? share->first_epoch : 0),
      report_(StartReport(options)),
      threads_(options.threads ? options.threads : CoresAllowed()),
      shares_(report_.memory_budget, threads_, options),
      // The first epoch, opened to learn what the series carries.
      source_(OpenSnapshot(options.inputs[0], options.read)),
      has_id_(source_->header().has_id),
      has_velocity_(source_->header().has_velocity),
      join_epochs_(has_id_ && options.inputs.size() > 1),
      manifest_(ManifestFor(options, has_id_, has_velocity_, join_epochs_)),
      output_guard_(output_),
      store_(output_, manifest_.ToJson(),
             AttributeSchema(has_velocity_, has_id_, join_epochs_, manifest_.has_velocity_dispersion, manifest_.has_shape),
             StoreOptions(options, share, false)),
      id_index_page_size_(std::max(options.page_size, kIdIndexMinPageSize)),
      screened_(options.inputs.size()) {
  if (has_id_) id_store_ = MakeIdStoreWriter(output_, StoreOptions(options, share, true));
  output_guard_.StoreLocked();
  // Inside the output by default: where this run may surely write, and where
  // a rerun finds it if a kill leaves it behind (TempDirectory). Made after
  // the store writers, which clear away an abandoned store first.
  temp_.emplace(options.temp_dir.empty() ? output_ : options.temp_dir, "octocosm-ingest");
  if (first_epoch_ > 0) source_.reset();  // opened at the share's first epoch
  group_ = group;
}

// The leaves' smoothing lengths from neighbours (or the snapshot's own),
// computed before anything else reads the epoch, in the whole budget (the
// pass is done with its memory before the epoch's build takes it, but for
// the lengths themselves: 4 bytes a particle, or a mapped file).
std::unique_ptr<ParticleSource> IngestRun::Smooth(std::unique_ptr<ParticleSource> raw) {
  if (options_.neighbours <= 0) return raw;
  SmoothingPassOptions pass;
  pass.neighbours = options_.neighbours;
  // Neighbours across the faces where ingest wraps into a periodic box.
  pass.box_size = options_.cube ? 0.0 : raw->header().box_size;
  pass.memory_budget = shares_.budget;
  pass.temp_dir = temp_->path();
  pass.threads = threads_;
  pass.quiet = options_.quiet;
  // A spread epoch: each rank reads a share of the snapshot's batches and
  // searches a share of the regions; its table holds the lengths of the
  // batches it reads, the only ones it reads again.
  pass.group = group_;
  std::unique_ptr<SmoothingLengthTable> table = ComputeSmoothingLengths(*raw, pass);
  return WithSmoothingLengths(std::move(raw), std::move(table));
}

// Each epoch screened (Screen) before anything else reads it; the smoothing
// pass then sees only the particles kept.
std::unique_ptr<ParticleSource> IngestRun::Prepare(std::unique_ptr<ParticleSource> raw, std::size_t e, PhaseClock* clock) {
  ScreenedEpoch s = Screen(std::move(raw), options_, "epoch " + std::to_string(e), group_);
  if (clock != nullptr && s.passes) clock->Lap("bounds");
  std::unique_ptr<ParticleSource> prepared = Smooth(std::move(s.source));
  screened_[e] = std::move(s);
  return prepared;
}

std::unique_ptr<SortedEpoch> IngestRun::SortEpoch(ParticleSource& source, std::size_t e) {
  Progress progress("epoch " + std::to_string(e) + ": sort by ID", source.header().total_count, "points");
  auto sorted = std::make_unique<SortedEpoch>(source, temp_->path() + "/sorted-" + std::to_string(e),
                                              shares_.sort_run_records, [&](std::uint64_t n) { progress.Add(n); });
  if (sorted->duplicate_ids() > 0) RefuseDuplicateIds(source.header(), sorted->first_duplicate_id(), sorted->duplicate_ids());
  progress.Finish();
  return sorted;
}

// Step 1: a series with IDs is sorted by ID, this epoch and the next (read
// ahead, and kept for the next epoch); otherwise the bounds come from the
// screening's survey.
Bounds IngestRun::SortOrBound(std::size_t e, PhaseClock& clock, EpochReport& epoch_report) {
  Bounds bounds;
  if (join_epochs_) {
    if (!sorted_current_) {
      sorted_current_ = SortEpoch(*source_, e);
      if (e == first_epoch_ && e > 0) LinkFromPrevious(e);
    }
    if (e + 1 < options_.inputs.size()) {
      if (options_.neighbours > 0) clock.Lap("sort");
      next_source_ = Prepare(OpenSnapshot(options_.inputs[e + 1], options_.read), e + 1, nullptr);
      if (options_.neighbours > 0) clock.Lap("next smoothing");
      sorted_next_ = SortEpoch(*next_source_, e + 1);
    }
    bounds = sorted_current_->bounds();
    epoch_report.duplicate_ids = sorted_current_->duplicate_ids();
    clock.Lap(next_source_ && options_.neighbours > 0 ? "next sort" : "sort");
  } else if (screened_[e].bounds) {
    bounds = *screened_[e].bounds;  // the survey's, before the smoothing pass
  }
  return bounds;
}

// The first epoch of a share after the first: the join of the epoch before
// it, read and sorted again here, writes this epoch's links back and counts
// what the previous epoch lacks, as the single run's join does.
void IngestRun::LinkFromPrevious(std::size_t e) {
  ScreenedEpoch previous = Screen(OpenSnapshot(options_.inputs[e - 1], options_.read), options_,
                                  "epoch " + std::to_string(e - 1));
  const std::unique_ptr<SortedEpoch> sorted = SortEpoch(*previous.source, e - 1);
  const Cube cube = ChooseCube(previous.source->header(), sorted->bounds());
  const JoinStats join = JoinedPass(*sorted, sorted_current_.get(), "", LinkFilePath(temp_->path(), e),
                                    cube.periodic ? cube.size : 0.0, options_.read.chunk_particles,
                                    [](const ParticleChunk&) {});
  missing_in_prev_ = join.new_in_next;
}

Cube IngestRun::ChooseCube(const SnapshotHeader& header, const Bounds& bounds) const {
  if (options_.cube) return *options_.cube;
  if (header.box_size > 0) return {{0, 0, 0}, header.box_size, true};
  if (!bounds.empty()) return Cube::FromBounds(bounds.lo, bounds.hi);
  return {};
}

// Chunks small enough for memory and the caches, and numerous enough (four
// per thread) that every core has work until the end, for `expected` points
// of `columns` (an epoch, or a spread epoch's domain).
ChunkerOptions IngestRun::ChunkerOptionsFor(std::uint64_t expected, const ParticleColumns& columns) {
  ChunkerOptions o;
  o.max_chunk_points =
      options_.max_chunk_points
          ? options_.max_chunk_points
          : std::min(shares_.build_points, std::max<std::uint64_t>(std::min(expected / (4 * threads_), kMaxChunkPoints),
                                                                   4 * options_.tree.capacity));
  report_.max_chunk_points = std::max(report_.max_chunk_points, o.max_chunk_points);
  o.split_levels = SplitLevelsFor(expected, o.max_chunk_points);
  o.max_level = options_.tree.max_level;
  o.leaf_capacity = options_.tree.capacity;
  o.memory_bytes = shares_.chunk_buffer_bytes;
  o.temp_dir = temp_->path();
  o.threads = static_cast<int>(threads_);
  o.columns = columns;
  return o;
}

// Step 2: the epoch read and cut into chunks (ChunkerOptionsFor).
ChunkedEpoch IngestRun::ChunkEpoch(const std::string& label, const SnapshotHeader& header, std::uint64_t expected,
                                   EpochPoints& points, EpochReport& epoch_report) {
  ParticleColumns columns;
  columns.id = has_id_;
  // Epoch by epoch: a series may give smoothing lengths in some snapshots only.
  columns.smoothing = header.has_smoothing;
  columns.vector(VectorColumn::kVelocity) = has_velocity_;
  columns.vector(VectorColumn::kDisplacement) = points.next != nullptr;
  columns.vector(VectorColumn::kNextVelocity) = points.next != nullptr && has_velocity_;
  columns.vector(VectorColumn::kPrevDisplacement) = !points.links_from_previous.empty();
  columns.vector(VectorColumn::kPrevVelocity) = !points.links_from_previous.empty() && has_velocity_;
  const ChunkerOptions chunker_options = ChunkerOptionsFor(expected, columns);
  const std::uint64_t max_chunk = chunker_options.max_chunk_points;
  const bool resident = !options_.stream_chunks && expected < UINT32_MAX &&
                        expected * chunker_options.columns.BytesPerPoint() <= shares_.ResidentBytes(join_epochs_) &&
                        expected * Chunker::kResidentScratchBytesPerPoint <= shares_.ResidentScratchBytes();
  ChunkedEpoch chunked{{}, ResidentEpoch(), IdCensus(shares_.id_table_slots)};
  Progress progress(label + ": read + chunk", expected, "points");
  PointPass counted = [&](const std::function<void(const ParticleChunk&)>& consume) {
    points.Pass([&](const ParticleChunk& chunk) {
      consume(chunk);
      chunked.ids.Add(chunk.id);
      progress.Add(chunk.size());
    });
  };
  Chunker chunker(points.cube, chunker_options);
  if (resident) {
    const bool mapped = !join_epochs_ && MapResident(*points.source, points.cube, chunker_options.columns, threads_,
                                                     chunked.resident, chunked.ids, progress);
    if (!mapped) chunked.resident.Read(counted, expected, chunker_options.columns);
    chunked.chunks = chunker.SplitTail(chunker.SplitResident(NodeKey::Root(), chunked.resident), chunked.resident,
                                       kQueueWindowPerThread * threads_, max_chunk / kTailChunkFraction);
  } else {
    chunked.chunks = chunker.Split(NodeKey::Root(), counted);
  }
  epoch_report.spilled_points = chunker.spilled_points();
  epoch_report.resident = resident;
  epoch_report.mapped = chunked.resident.mapped();
  return chunked;
}

// What the join to the next epoch found: missing particles and the fit of
// the curves between the two.
void IngestRun::RecordLinks(const EpochPoints& points, EpochReport& epoch_report) {
  const JoinStats& join = points.join_stats;
  epoch_report.missing_in_next = join.missing_in_next;
  epoch_report.missing_in_prev = missing_in_prev_;
  missing_in_prev_ = join.new_in_next;
  if (points.next == nullptr) return;
  const VelocityScaleFit& fit = join.fit;
  // A Hermite curve strays from its chord by at most 4/27 of each tangent
  // (the peak of the basis functions h10 and h11).
  const double excursion = join.max_displacement + 4.0 / 27.0 * std::fabs(fit.velocity_scale()) * join.max_speed_sum;
  epoch_report.to_next = EpochLink{fit.velocity_scale(), fit.fit_residual(), fit.least_squares_scale(),
                                   fit.inlier_fraction(), join.matched, excursion};
}

// Step 5, the ID index. It needs only the leaves, so it is written on a
// thread of its own from when the last chunk is built, while the merger
// closes the nodes above it, and while the epoch's page file is finished
// (mostly waiting for fsync). The store and the ID store share no state.
void IngestRun::WriteIdIndex(const SnapshotHeader& header, DenseIdTable* id_table,
                             ExternalSorter<IdLeafRecord>* id_pairs) {
  if (id_pairs != nullptr) id_pairs->Finish();
  id_store_->BeginEpoch(header.time, header.redshift);
  IdIndexEpochWriter ids(*id_store_, id_index_page_size_);
  if (id_table != nullptr) {
    id_table->SortLeaves(static_cast<int>(threads_));
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
  id_store_->EndEpoch();
}

// Steps 3 and 4: the chunks' subtrees and the levels above them into the
// store; step 5 beside them.
void IngestRun::BuildAndWrite(std::size_t e, const SnapshotHeader& header, const Cube& cube, ChunkedEpoch& chunked,
                              EpochReport& epoch_report, PhaseClock& clock) {
  store_.BeginEpoch(header.time, header.redshift);
  std::unique_ptr<DenseIdTable> id_table;
  std::unique_ptr<ExternalSorter<IdLeafRecord>> id_pairs;
  if (has_id_ && chunked.ids.dense() && chunked.ids.count() == epoch_report.points) {
    id_table = std::make_unique<DenseIdTable>(chunked.ids.first(), chunked.ids.span());
  } else if (has_id_) {
    epoch_report.ids_sorted = true;
    id_pairs = std::make_unique<ExternalSorter<IdLeafRecord>>(temp_->path() + "/ids-" + std::to_string(e),
                                                             shares_.id_run_records);
    id_pairs->Reserve(static_cast<std::size_t>(epoch_report.points));
  }
  EpochBuild build;
  build.cube = &cube;
  build.tree = &options_.tree;
  build.store = &store_;
  build.header = &header;
  build.id_table = id_table.get();
  build.id_pairs = id_pairs.get();
  build.report = &epoch_report;
  std::future<void> id_index_written;
  {
    Progress progress("epoch " + std::to_string(e) + ": build", epoch_report.points, "points");
    build.progress = &progress;
    const NodePoints root = BuildChunks(std::move(chunked.chunks), chunked.resident, build, threads_, [&] {
      if (has_id_) {
        id_index_written = std::async(std::launch::async, [&] { WriteIdIndex(header, id_table.get(), id_pairs.get()); });
      }
    });
    chunked.resident = ResidentEpoch();
    for (double w : root.weight) epoch_report.mass += w;
    progress.Finish();
  }
  clock.Lap("build");
  std::future<void> epoch_written = std::async(std::launch::async, [this] { store_.EndEpoch(); });
  if (has_id_) {
    id_index_written.get();
    clock.Lap("ids");
  }
  epoch_written.get();
  clock.Lap("write");
}

EpochRecord RecordOf(const SnapshotHeader& header, const Cube& cube, const EpochReport& r) {
  EpochRecord record;
  record.input = HeaderJson(header);
  record.cube = cube;
  record.summary.points = r.points;
  record.summary.mass = r.mass;
  record.summary.nodes = r.nodes;
  record.summary.leaves = r.leaves;
  record.summary.depth = r.depth;
  record.missing_in_next = r.missing_in_next;
  record.missing_in_prev = r.missing_in_prev;
  record.duplicate_ids = r.duplicate_ids;
  record.to_next = r.to_next;
  return record;
}

void IngestRun::IngestEpoch(std::size_t e) {
  if (group_ != nullptr) return IngestSpreadEpoch(e);
  if (!source_) source_ = OpenSnapshot(options_.inputs[e], options_.read);
  EpochReport epoch_report;
  PhaseClock clock(epoch_report);
  if (!source_smoothed_) {
    source_ = Prepare(std::move(source_), e, &clock);
    if (options_.neighbours > 0) clock.Lap("smoothing");
  }
  const SnapshotHeader header = source_->header();
  if (header.has_id != has_id_ || header.has_velocity != has_velocity_) {
    throw Error::BadInput(header.files.front(), "this epoch " + std::string(header.has_id ? "has" : "lacks") +
                                                    " IDs / velocities unlike epoch 0; all epochs of a series must carry the same columns");
  }
  const Bounds bounds = SortOrBound(e, clock, epoch_report);
  EpochPoints points;
  points.source = source_.get();
  points.current = join_epochs_ ? sorted_current_.get() : nullptr;
  points.next = sorted_next_.get();
  points.cube = ChooseCube(header, bounds);
  points.links_from_previous = join_epochs_ && e > 0 ? LinkFilePath(temp_->path(), e) : "";
  points.links_to_next = points.next != nullptr ? LinkFilePath(temp_->path(), e + 1) : "";
  points.chunk_particles = options_.read.chunk_particles;

  const std::uint64_t expected = join_epochs_ ? bounds.count : header.total_count;
  ChunkedEpoch chunked = ChunkEpoch("epoch " + std::to_string(e), header, expected, points, epoch_report);
  clock.Lap("read+chunk");
  if (has_id_ && chunked.ids.repeated_id()) RefuseDuplicateIds(header, *chunked.ids.repeated_id(), 0);
  for (const Chunk& c : chunked.chunks) epoch_report.points += c.point_count;
  epoch_report.read_points = screened_[e].read;
  epoch_report.dropped_points = screened_[e].dropped;
  epoch_report.chunks = chunked.chunks.size();
  if (!points.links_from_previous.empty()) std::remove(points.links_from_previous.c_str());
  RecordLinks(points, epoch_report);

  BuildAndWrite(e, header, points.cube, chunked, epoch_report, clock);
  manifest_.epochs.push_back(RecordOf(header, points.cube, epoch_report));
  report_.input_points += epoch_report.points;
  report_.read_points += epoch_report.read_points;
  report_.dropped_points += epoch_report.dropped_points;
  report_.epochs.push_back(epoch_report);

  // The next epoch reuses what this one read ahead.
  sorted_current_ = std::move(sorted_next_);
  source_ = std::move(next_source_);
  source_smoothed_ = source_ != nullptr;
}

// ---- One epoch spread over ranks (IngestSpreadInto) ----
//
//   1. count   each rank reads its share of the snapshot's batches and counts
//              them on the domains' grid; the counts are summed over the
//              ranks, and every rank cuts the same domains from them
//              (ingest/epoch_domains.h)
//   2. exchange each rank reads its share again and sends every particle to
//              the rank of its domain, a batch a rank per round, so each
//              round holds a few batches whatever the epoch's size; each
//              rank files what it receives by domain
//   3. build   each rank chunks and builds its domains' subtrees one domain
//              after the other, as a single process builds its chunks; rank
//              0 merges the levels above every rank's domains from their roots
//   4. ids     each rank writes the ID index's buckets of a run of IDs,
//              from every rank's leaves (ingest/spread_id_index.h)
//   5. gather  rank 0 makes room for the others' blocks and buckets in its
//              page files, where each rank copies its own, as they are, at
//              once; rank 0's part is then the epoch a single process writes
// Every rank screens the whole epoch alike first, so that all choose the
// same cube, and the ranks share the neighbour pass.

struct IngestRun::SpreadCensus {
  std::vector<std::uint64_t> cells;  // points in each cell of the domains' grid, summed over the ranks
  // The epoch's IDs over all ranks, as one process's IdCensus would see them.
  std::uint64_t id_count = 0, id_first = 0, id_last = 0;
  bool ids_dense = true;
};

IngestRun::SpreadCensus IngestRun::CountForDomains(const std::string& label, EpochPoints& points,
                                                   const PointPass& my_batches, std::uint64_t& batches) {
  RankGroup& group = *group_;
  const int level = DomainGridLevel(options_.tree.max_level);
  SpreadCensus census;
  census.cells.assign(std::size_t{1} << (3 * level), 0);
  IdCensus ids(shares_.id_table_slots);
  {
    Progress progress(label + ": count", points.source->header().total_count / static_cast<std::uint64_t>(group.size()),
                      "points");
    std::uint64_t seen = 0;
    my_batches([&](const ParticleChunk& chunk) {
      for (std::size_t i = 0; i < chunk.size(); ++i) {
        ++census.cells[EpochDomains::CellIndex(points.cube, &chunk.position[3 * i], level)];
      }
      ids.Add(chunk.id);
      progress.Add(chunk.size());
      ++seen;
    });
    progress.Finish();
    batches = seen;
  }
  group.Sum(census.cells);
  // batches: this rank's; every rank needs rank 0's, the most.
  std::uint64_t counts[2] = {ids.count(), 0};
  std::uint64_t most[6] = {ids.dense() ? 0u : 1u, ids.count() > 0 ? ~ids.first() : 0, ids.count() > 0 ? ids.first() + ids.span() - 1 : 0,
                           ids.repeated_id() ? 1u : 0u, ids.repeated_id() ? *ids.repeated_id() : 0, batches};
  group.Sum(counts);
  group.Max(most);
  if (most[3] != 0) RefuseDuplicateIds(points.source->header(), most[4], 0);
  batches = most[5];
  census.id_count = counts[0];
  if (census.id_count > 0) {
    census.id_first = ~most[1];
    census.id_last = most[2];
  }
  census.ids_dense = most[0] == 0 && (census.id_count == 0 || census.id_last - census.id_first < shares_.id_table_slots);
  return census;
}

// Step 2; returns the files of this rank's domains, in the order of
// domains.DomainsOf(rank).
std::vector<IngestRun::DomainFile> IngestRun::ExchangeToDomains(const std::string& label, EpochPoints& points,
                                                                const PointPass& my_batches, std::uint64_t rounds,
                                                                const EpochDomains& domains,
                                                                const ParticleColumns& columns) {
  RankGroup& group = *group_;
  const int rank = group.rank();
  std::size_t first_mine = 0;
  while (first_mine < domains.owner.size() && domains.owner[first_mine] < rank) ++first_mine;
  const std::size_t mine = domains.DomainsOf(rank).size();
  std::vector<ParticleFileWriter> writers;
  for (std::size_t k = 0; k < mine; ++k) {
    writers.emplace_back(temp_->path() + "/domain-" + std::to_string(k), columns);
  }
  Progress progress(label + ": exchange", points.source->header().total_count / static_cast<std::uint64_t>(group.size()),
                    "points");
  std::vector<std::pair<std::uint32_t, std::uint32_t>> by_domain;  // (domain, point)
  std::vector<std::uint32_t> indices;
  auto exchange = [&](const ParticleChunk* chunk) {
    std::vector<Bytes> outgoing(static_cast<std::size_t>(group.size()));
    if (chunk != nullptr) {
      by_domain.clear();
      for (std::size_t i = 0; i < chunk->size(); ++i) {
        const std::uint64_t cell = EpochDomains::CellIndex(points.cube, &chunk->position[3 * i], domains.level);
        by_domain.push_back({domains.cell_domain[cell], static_cast<std::uint32_t>(i)});
      }
      std::sort(by_domain.begin(), by_domain.end());
      for (std::size_t a = 0; a < by_domain.size();) {
        std::size_t b = a;
        indices.clear();
        for (; b < by_domain.size() && by_domain[b].first == by_domain[a].first; ++b) indices.push_back(by_domain[b].second);
        const std::uint32_t d = by_domain[a].first;
        AppendPointSegment(d, *chunk, indices, columns, outgoing[static_cast<std::size_t>(domains.owner[d])]);
        a = b;
      }
    }
    const std::vector<Bytes> incoming = group.Exchange(outgoing);
    for (const Bytes& message : incoming) {
      ForEachPointSegment(message, columns, label.c_str(), [&](std::uint32_t d, const ParticleChunk& received) {
        if (d < first_mine || d >= first_mine + mine) {
          throw Error::Corruption(label, "particles for domain " + std::to_string(d) + " reached rank " +
                                             std::to_string(rank) + ", which does not hold it");
        }
        writers[d - first_mine].Append(received);
        progress.Add(received.size());
      });
    }
  };
  std::uint64_t round = 0;
  my_batches([&](const ParticleChunk& chunk) {
    exchange(&chunk);
    ++round;
  });
  // Every rank takes part in every round, with nothing to send once its share is sent.
  for (; round < rounds; ++round) exchange(nullptr);
  std::vector<DomainFile> files;
  for (ParticleFileWriter& writer : writers) {
    writer.Close();
    files.push_back({writer.path(), writer.point_count()});
  }
  return files;
}

// Step 3: this rank's domains, each chunked and built as a single process
// builds an epoch; their roots go to rank 0's merger `top` (on rank 0) or are
// sent to rank 0 once all are built (elsewhere: rank 0 merges them after
// its own).
void IngestRun::BuildDomains(const std::string& label, const Cube& cube, const std::vector<NodeKey>& mine,
                             const std::vector<DomainFile>& files, const ParticleColumns& columns, EpochBuild& build,
                             EpochReport& epoch_report, TopLevelMerger* top) {
  std::uint64_t total = 0;
  std::vector<std::uint64_t> counts;
  for (const DomainFile& file : files) {
    counts.push_back(file.points);
    total += file.points;
  }
  Progress progress(label + ": build", total, "points");
  build.progress = &progress;
  MessageFile roots(temp_->path() + "/domain-roots");
  const ResidentEpoch none;
  for (std::size_t k = 0; k < mine.size(); ++k) {
    Chunker chunker(cube, ChunkerOptionsFor(counts[k], columns));
    const std::string& file = files[k].path;
    std::vector<Chunk> chunks = chunker.Split(mine[k], [&file](const std::function<void(const ParticleChunk&)>& consume) {
      ParticleFileReader reader(file);
      ParticleChunk batch;
      while (reader.Next(batch)) consume(batch);
    });
    std::remove(file.c_str());
    epoch_report.chunks += chunks.size();
    epoch_report.spilled_points += chunker.spilled_points();
    for (const Chunk& c : chunks) epoch_report.points += c.point_count;
    NodePoints root;
    build.domain = mine[k];
    build.domain_root = &root;
    BuildChunks(std::move(chunks), none, build, threads_, [] {});
    build.domain = NodeKey();
    build.domain_root = nullptr;
    if (top != nullptr) {
      top->Add(mine[k], std::move(root));
    } else {
      roots.Add(PackNode(mine[k], root));
    }
  }
  progress.Finish();
  if (top != nullptr) return;
  const std::uint64_t count = roots.count();
  group_->Send(0, Bytes(reinterpret_cast<const std::uint8_t*>(&count), reinterpret_cast<const std::uint8_t*>(&count + 1)));
  roots.ForEach([this](const Bytes& root) { group_->Send(0, root); });
}

// Step 3, on rank 0: the other ranks' domain roots into `top`, in rank
// order (depth-first order: ranks hold consecutive runs of domains), and
// the levels above them.
void IngestRun::MergeOtherRanksRoots(const std::string& label, EpochReport& epoch_report, TopLevelMerger& top,
                                     PhaseClock& clock) {
  RankGroup& group = *group_;
  for (int r = 1; r < group.size(); ++r) {
    const std::string what = label + ": rank " + std::to_string(r);
    const Bytes count_message = group.Receive(r);
    std::uint64_t count = 0;
    if (count_message.size() != sizeof count) throw Error::Corruption(what, "a malformed count of domains");
    std::memcpy(&count, count_message.data(), sizeof count);
    for (std::uint64_t k = 0; k < count; ++k) {
      NodeKey key;
      NodePoints root = UnpackNode(group.Receive(r), key, what.c_str());
      top.Add(key, std::move(root));
    }
  }
  // Until here mostly waiting for the other ranks' builds.
  clock.Lap("wait");
  const NodePoints root = top.Finish();
  for (double w : root.weight) epoch_report.mass += w;
}

// Step 4, on every rank: its share of the ID index, from every rank's
// leaves, into its ID store's epoch (ingest/spread_id_index.h).
void IngestRun::WriteIdIndexShare(const SnapshotHeader& header, const SpreadCensus& census, LeafIdsFile& leaf_ids,
                                  EpochReport& epoch_report) {
  SpreadIdIndexOptions options;
  options.page_size = id_index_page_size_;
  options.table = census.ids_dense && census.id_count > 0;
  options.table_first = census.id_first;
  options.table_span = options.table ? census.id_last - census.id_first + 1 : 0;
  options.round_pairs = static_cast<std::size_t>(options_.read.chunk_particles);
  options.temp_prefix = temp_->path() + "/ids";
  // The build is over: the pairs may take half the budget (the other half
  // is the rounds' messages and the merge's buffers).
  options.sort_memory = shares_.budget / 2;
  options.refuse_repeated_id = [&header](std::uint64_t id) { RefuseDuplicateIds(header, id, 0); };
  epoch_report.ids_sorted = !options.table;
  id_store_->BeginEpoch(header.time, header.redshift);
  WriteSpreadIdIndex(*group_, leaf_ids, *id_store_, options);
}

// Step 5, on rank 0: room in the store's page files for the other ranks'
// blocks and ID index buckets, which they copy in themselves.
void IngestRun::GatherOtherRanks(const std::string& label, EpochReport& epoch_report) {
  RankGroup& group = *group_;
  for (int r = 1; r < group.size(); ++r) {
    const std::string what = label + ": rank " + std::to_string(r);
    const Bytes message = group.Receive(r);
    IngestPart part;
    try {
      part = IngestPart::FromJson(nlohmann::json::parse(message.begin(), message.end()), what);
      const EpochReport& built = part.report.epochs.at(0);
      epoch_report.points += built.points;
      epoch_report.chunks += built.chunks;
      epoch_report.spilled_points += built.spilled_points;
      epoch_report.nodes += built.nodes;
      epoch_report.leaves += built.leaves;
      epoch_report.depth = std::max(epoch_report.depth, built.depth);
    } catch (const nlohmann::json::exception& e) {
      throw Error::Corruption(what, std::string("not a summary of a rank's part: ") + e.what());
    } catch (const std::out_of_range&) {
      throw Error::Corruption(what, "a summary of a rank's part without its epoch");
    }
    if (part.epochs.size() != 1 || part.id_epochs.size() != (has_id_ ? 1u : 0u)) {
      throw Error::Corruption(what, "a summary of a rank's part with " + std::to_string(part.epochs.size()) +
                                        " epochs and " + std::to_string(part.id_epochs.size()) + " of IDs");
    }
    nlohmann::json order;
    const std::string pages = (fs::path(part.directory) / part.epochs[0].file).string();
    order["target"] = store_.open_epoch_temporary_path();
    order["offset"] = store_.ReserveBlocksOf(*PageFileReader::Open(pages));
    if (has_id_) {
      const std::string id_pages = (fs::path(part.directory) / "ids" / part.id_epochs[0].file).string();
      order["id_target"] = id_store_->open_epoch_temporary_path();
      order["id_offset"] = id_store_->ReserveBlocksOf(*PageFileReader::Open(id_pages));
    }
    const std::string order_text = order.dump();
    group.Send(r, Bytes(order_text.begin(), order_text.end()));
  }
  for (int r = 1; r < group.size(); ++r) {
    const Bytes answer = group.Receive(r);
    if (!answer.empty()) {
      throw Error::Io(label + ": rank " + std::to_string(r), "copying its blocks into the store failed: " +
                                                                  std::string(answer.begin(), answer.end()));
    }
  }
}

void IngestRun::IngestSpreadEpoch(std::size_t e) {
  RankGroup& group = *group_;
  const int rank = group.rank(), ranks = group.size();
  const std::string label = "epoch " + std::to_string(e);
  if (!source_) source_ = OpenSnapshot(options_.inputs[e], options_.read);
  EpochReport epoch_report;
  PhaseClock clock(epoch_report);
  source_ = Prepare(std::move(source_), e, &clock);
  if (options_.neighbours > 0) clock.Lap("smoothing");
  const SnapshotHeader header = source_->header();
  EpochPoints points;
  points.source = source_.get();
  points.cube = ChooseCube(header, screened_[e].bounds.value_or(Bounds{}));
  points.chunk_particles = options_.read.chunk_particles;
  // This rank's share of the snapshot: every ranks-th batch, from the rank-th.
  const PointPass my_batches = [&](const std::function<void(const ParticleChunk&)>& consume) {
    points.PassShare(static_cast<std::uint64_t>(ranks), static_cast<std::uint64_t>(rank), consume);
  };

  std::uint64_t rounds = 0;
  const SpreadCensus census = CountForDomains(label, points, my_batches, rounds);
  const EpochDomains domains = ShareDomains(census.cells, DomainGridLevel(options_.tree.max_level),
                                            options_.tree.capacity, ranks);
  clock.Lap("count");

  ParticleColumns columns;
  columns.id = has_id_;
  columns.smoothing = header.has_smoothing;
  columns.vector(VectorColumn::kVelocity) = has_velocity_;
  const std::vector<NodeKey> mine = domains.DomainsOf(rank);
  const std::vector<DomainFile> files = ExchangeToDomains(label, points, my_batches, rounds, domains, columns);
  clock.Lap("exchange");

  store_.BeginEpoch(header.time, header.redshift);
  std::unique_ptr<LeafIdsFile> leaf_ids;
  if (has_id_) leaf_ids = std::make_unique<LeafIdsFile>(temp_->path() + "/leaf-ids-" + std::to_string(e));
  EpochBuild build;
  build.cube = &points.cube;
  build.tree = &options_.tree;
  build.store = &store_;
  build.header = &header;
  build.leaf_ids = leaf_ids.get();
  build.report = &epoch_report;
  Bytes top_block;
  std::optional<TopLevelMerger> top;
  if (rank == 0) {
    top.emplace(points.cube, options_.tree, [&build, &top_block](NodeKey key, const NodePoints& node) {
      build.Emit(key, node, /*is_leaf=*/false, top_block);
    });
  }
  BuildDomains(label, points.cube, mine, files, columns, build, epoch_report, top ? &*top : nullptr);
  clock.Lap("build");
  if (rank == 0) MergeOtherRanksRoots(label, epoch_report, *top, clock);
  if (leaf_ids) {
    leaf_ids->Close();
    WriteIdIndexShare(header, census, *leaf_ids, epoch_report);
    leaf_ids.reset();
    clock.Lap("ids");
  }
  if (rank != 0) {
    if (id_store_) id_store_->EndEpoch();
    store_.EndEpoch();
    spread_report_ = epoch_report;
    manifest_.epochs.push_back(RecordOf(header, points.cube, epoch_report));
    report_.epochs.push_back(epoch_report);
    return;
  }
  GatherOtherRanks(label, epoch_report);
  clock.Lap("gather");
  if (id_store_) id_store_->EndEpoch();
  store_.EndEpoch();
  clock.Lap("write");
  epoch_report.read_points = screened_[e].read;
  epoch_report.dropped_points = screened_[e].dropped;
  manifest_.epochs.push_back(RecordOf(header, points.cube, epoch_report));
  report_.input_points += epoch_report.points;
  report_.read_points += epoch_report.read_points;
  report_.dropped_points += epoch_report.dropped_points;
  report_.epochs.push_back(epoch_report);
  source_.reset();
}

void IngestRun::SendSpreadSummary(const IngestPart& part) {
  const std::string text = part.ToJson().dump();
  group_->Send(0, Bytes(text.begin(), text.end()));
}

void IngestRun::CopyBlocksForRankZero(const IngestPart& part) {
  const Bytes message = group_->Receive(0);
  std::string failure;
  try {
    const nlohmann::json order = nlohmann::json::parse(message.begin(), message.end());
    CopyBlockPages((fs::path(part.directory) / part.epochs.at(0).file).string(),
                   order.at("target").get<std::string>(), order.at("offset").get<std::uint64_t>());
    if (order.contains("id_target")) {
      CopyBlockPages((fs::path(part.directory) / "ids" / part.id_epochs.at(0).file).string(),
                     order.at("id_target").get<std::string>(), order.at("id_offset").get<std::uint64_t>());
    }
  } catch (const std::exception& e) {
    // Rank 0 ends the ingest with it, removing what the ranks wrote.
    failure = e.what();
    if (failure.empty()) failure = "an unnamed error";
  }
  group_->Send(0, Bytes(failure.begin(), failure.end()));
}

IngestPart IngestRun::FinishPart() {
  IngestPart part;
  part.directory = output_;
  if (id_store_) part.id_epochs = id_store_->FinishPart();
  part.epochs = store_.FinishPart();
  output_guard_.Commit();
  part.records = manifest_.epochs;
  report_.store_bytes = store_.bytes_written() + (id_store_ ? id_store_->bytes_written() : 0);
  report_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  part.report = report_;
  return part;
}

IngestReport IngestRun::Finish() {
  if (id_store_) id_store_->Finish();
  store_.SetDataset(manifest_.ToJson());
  store_.Finish();
  output_guard_.Commit();
  report_.store_bytes = store_.bytes_written() + (id_store_ ? id_store_->bytes_written() : 0);
  report_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  return report_;
}

}  // namespace

std::uint64_t DefaultMemoryBudget() {
  const long pages = ::sysconf(_SC_PHYS_PAGES);
  const long page_size = ::sysconf(_SC_PAGE_SIZE);
  const std::uint64_t physical = pages > 0 && page_size > 0 ? static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page_size) : 0;
  return std::max<std::uint64_t>(physical / 2, std::uint64_t{256} << 20);
}

// The pipeline: for each epoch, screen and smooth, sort or bound, chunk,
// build, write (IngestRun::IngestEpoch); then the manifest.
IngestReport Ingest(const IngestOptions& options) {
  IngestRun run(options);
  for (std::size_t e = 0; e < options.inputs.size(); ++e) run.IngestEpoch(e);
  return run.Finish();
}

IngestPart IngestShareInto(const IngestOptions& options, const IngestShare& share, const std::string& part_directory) {
  if (share.first_epoch > share.end_epoch || share.end_epoch > options.inputs.size()) {
    throw Error::InvalidArgument("ingest: a share of epochs [" + std::to_string(share.first_epoch) + ", " +
                                 std::to_string(share.end_epoch) + ") of a series of " +
                                 std::to_string(options.inputs.size()));
  }
  if (share.first_epoch == share.end_epoch) {
    IngestPart part;
    part.directory = part_directory;
    return part;
  }
  IngestRun run(options, &share, part_directory);
  for (std::size_t e = share.first_epoch; e < share.end_epoch; ++e) run.IngestEpoch(e);
  return run.FinishPart();
}

IngestPart IngestSpreadInto(const IngestOptions& options, const IngestShare& share, RankGroup& group,
                            const std::string& part_directory) {
  if (options.inputs.size() != 1 || share.first_epoch != 0 || share.end_epoch != 1) {
    throw Error::InvalidArgument("ingest: only a single epoch is spread over ranks (" +
                                 std::to_string(options.inputs.size()) + " given)");
  }
  IngestRun run(options, &share, part_directory, &group);
  run.IngestEpoch(0);
  IngestPart part = run.FinishPart();
  if (group.rank() == 0) return part;
  run.SendSpreadSummary(part);
  run.CopyBlocksForRankZero(part);
  part.epochs.clear();
  part.id_epochs.clear();
  part.records.clear();
  part.report.epochs.clear();
  return part;
}

namespace {

// What the series carries, from its first snapshot's header.
struct SeriesColumns {
  bool has_id = false, has_velocity = false, join_epochs = false;
};

SeriesColumns ColumnsOf(const IngestOptions& options) {
  const std::unique_ptr<ParticleSource> first = OpenSnapshot(options.inputs.front(), options.read);
  SeriesColumns c;
  c.has_id = first->header().has_id;
  c.has_velocity = first->header().has_velocity;
  c.join_epochs = c.has_id && options.inputs.size() > 1;
  return c;
}

}  // namespace

struct IngestAssembly::Output {
  explicit Output(const IngestOptions& options)
      : report(StartReport(options)),
        columns(ColumnsOf(options)),
        manifest(ManifestFor(options, columns.has_id, columns.has_velocity, columns.join_epochs)),
        guard(options.output),
        store(options.output, manifest.ToJson(),
              AttributeSchema(columns.has_velocity, columns.has_id, columns.join_epochs,
                              manifest.has_velocity_dispersion, manifest.has_shape),
              StoreOptions(options, nullptr, false)) {
    if (columns.has_id) id_store = MakeIdStoreWriter(options.output, StoreOptions(options, nullptr, true));
    guard.StoreLocked();
  }

  const std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
  IngestReport report;
  SeriesColumns columns;
  DatasetManifest manifest;
  // Declared in the order they must be made; destroyed the other way round.
  OutputGuard guard;
  StoreWriter store;
  std::unique_ptr<StoreWriter> id_store;
  std::size_t parts = 0;
  std::optional<RemoveOnInterrupt> remove_parts;
  bool assembled = false;
};

IngestAssembly::IngestAssembly(const IngestOptions& options, std::size_t parts)
    : options_(options), output_(std::make_unique<Output>(options)) {
  output_->parts = parts;
  output_->remove_parts.emplace([this] {
    std::error_code ignored;
    for (std::size_t k = 0; k < output_->parts; ++k) fs::remove_all(PartDirectory(options_.output, k), ignored);
  });
}

IngestAssembly::~IngestAssembly() {
  output_->remove_parts.reset();
  if (output_->assembled) return;
  std::error_code ignored;
  for (std::size_t k = 0; k < output_->parts; ++k) fs::remove_all(PartDirectory(options_.output, k), ignored);
}

std::uint64_t IngestAssembly::store_id() const { return output_->store.store_id(); }

std::uint64_t IngestAssembly::id_store_id() const { return output_->id_store ? output_->id_store->store_id() : 0; }

IngestShare IngestAssembly::Share(std::size_t epochs, std::size_t part, std::size_t parts) {
  if (parts == 0 || part >= parts) {
    throw Error::InvalidArgument("ingest: no share " + std::to_string(part) + " of " + std::to_string(parts));
  }
  IngestShare share;
  share.first_epoch = epochs * part / parts;
  share.end_epoch = epochs * (part + 1) / parts;
  return share;
}

std::string IngestAssembly::PartDirectory(const std::string& output, std::size_t part) {
  return (fs::path(output) / ("octocosm-part-" + std::to_string(part))).string();
}

IngestReport IngestAssembly::Assemble(const std::vector<IngestPart>& parts) {
  Output& out = *output_;
  for (std::size_t k = 0; k < parts.size(); ++k) {
    const IngestPart& part = parts[k];
    if (part.records.size() != part.epochs.size() || (out.id_store && part.id_epochs.size() != part.epochs.size())) {
      throw Error::InvalidArgument("ingest: part " + std::to_string(k) + " (" + part.directory +
                                   ") describes its epochs inconsistently");
    }
    out.store.AdoptEpochs(part.directory, part.epochs);
    if (out.id_store) out.id_store->AdoptEpochs((fs::path(part.directory) / "ids").string(), part.id_epochs);
    out.manifest.epochs.insert(out.manifest.epochs.end(), part.records.begin(), part.records.end());
    const IngestReport& r = part.report;
    out.report.epochs.insert(out.report.epochs.end(), r.epochs.begin(), r.epochs.end());
    out.report.input_points += r.input_points;
    out.report.read_points += r.read_points;
    out.report.dropped_points += r.dropped_points;
    out.report.max_chunk_points = std::max(out.report.max_chunk_points, r.max_chunk_points);
  }
  if (out.manifest.epochs.size() != options_.inputs.size()) {
    throw Error::InvalidArgument("ingest: the parts hold " + std::to_string(out.manifest.epochs.size()) +
                                 " epochs of the series' " + std::to_string(options_.inputs.size()));
  }
  if (out.id_store) out.id_store->Finish();
  out.store.SetDataset(out.manifest.ToJson());
  out.store.Finish();
  out.guard.Commit();
  out.assembled = true;
  out.remove_parts.reset();
  std::error_code ignored;
  for (std::size_t k = 0; k < out.parts; ++k) fs::remove_all(PartDirectory(options_.output, k), ignored);
  out.report.store_bytes = out.store.bytes_written() + (out.id_store ? out.id_store->bytes_written() : 0);
  out.report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - out.start).count();
  return out.report;
}

namespace {

nlohmann::json EpochInfoJson(const EpochInfo& e) {
  return {{"epoch", e.epoch}, {"file", e.file}, {"time", e.time}, {"redshift", e.redshift},
          {"block_count", e.block_count}, {"file_size", e.file_size}};
}

EpochInfo EpochInfoFromJson(const nlohmann::json& j) {
  EpochInfo e;
  e.epoch = j.at("epoch").get<std::uint32_t>();
  e.file = j.at("file").get<std::string>();
  e.time = j.at("time").get<double>();
  e.redshift = j.at("redshift").get<double>();
  e.block_count = j.at("block_count").get<std::uint64_t>();
  e.file_size = j.at("file_size").get<std::uint64_t>();
  return e;
}

nlohmann::json EpochReportJson(const EpochReport& r) {
  nlohmann::json phases = nlohmann::json::array();
  for (const EpochReport::Phase& p : r.phases) phases.push_back({p.name, p.seconds, p.cpu_seconds});
  nlohmann::json j = {{"points", r.points}, {"read_points", r.read_points}, {"dropped_points", r.dropped_points},
                      {"nodes", r.nodes}, {"leaves", r.leaves}, {"chunks", r.chunks},
                      {"spilled_points", r.spilled_points}, {"resident", r.resident}, {"mapped", r.mapped},
                      {"phases", phases}, {"depth", r.depth}, {"mass", r.mass},
                      {"missing_in_next", r.missing_in_next}, {"missing_in_prev", r.missing_in_prev},
                      {"duplicate_ids", r.duplicate_ids}, {"ids_sorted", r.ids_sorted}};
  if (r.to_next) {
    const EpochLink& l = *r.to_next;
    j["to_next"] = {l.velocity_scale, l.fit_residual, l.least_squares_scale, l.inlier_fraction, l.matched, l.max_excursion};
  }
  return j;
}

EpochReport EpochReportFromJson(const nlohmann::json& j) {
  EpochReport r;
  r.points = j.at("points").get<std::uint64_t>();
  r.read_points = j.at("read_points").get<std::uint64_t>();
  r.dropped_points = j.at("dropped_points").get<std::uint64_t>();
  r.nodes = j.at("nodes").get<std::uint64_t>();
  r.leaves = j.at("leaves").get<std::uint64_t>();
  r.chunks = j.at("chunks").get<std::uint64_t>();
  r.spilled_points = j.at("spilled_points").get<std::uint64_t>();
  r.resident = j.at("resident").get<bool>();
  r.mapped = j.at("mapped").get<bool>();
  for (const auto& p : j.at("phases")) {
    r.phases.push_back({p.at(0).get<std::string>(), p.at(1).get<double>(), p.at(2).get<double>()});
  }
  r.depth = j.at("depth").get<int>();
  r.mass = j.at("mass").get<double>();
  r.missing_in_next = j.at("missing_in_next").get<std::uint64_t>();
  r.missing_in_prev = j.at("missing_in_prev").get<std::uint64_t>();
  r.duplicate_ids = j.at("duplicate_ids").get<std::uint64_t>();
  r.ids_sorted = j.at("ids_sorted").get<bool>();
  if (j.contains("to_next")) {
    const auto& l = j.at("to_next");
    r.to_next = EpochLink{l.at(0).get<double>(), l.at(1).get<double>(), l.at(2).get<double>(),
                          l.at(3).get<double>(), l.at(4).get<std::uint64_t>(), l.at(5).get<double>()};
  }
  return r;
}

}  // namespace

nlohmann::json IngestPart::ToJson() const {
  nlohmann::json epoch_list = nlohmann::json::array(), id_list = nlohmann::json::array();
  nlohmann::json record_list = nlohmann::json::array(), report_list = nlohmann::json::array();
  for (const EpochInfo& e : epochs) epoch_list.push_back(EpochInfoJson(e));
  for (const EpochInfo& e : id_epochs) id_list.push_back(EpochInfoJson(e));
  for (std::size_t i = 0; i < records.size(); ++i) record_list.push_back(records[i].ToJson(i));
  for (const EpochReport& r : report.epochs) report_list.push_back(EpochReportJson(r));
  return {{"directory", directory},
          {"epochs", epoch_list},
          {"id_epochs", id_list},
          {"records", record_list},
          {"report",
           {{"epochs", report_list}, {"input_points", report.input_points}, {"read_points", report.read_points},
            {"dropped_points", report.dropped_points}, {"store_bytes", report.store_bytes},
            {"max_chunk_points", report.max_chunk_points}, {"memory_budget", report.memory_budget},
            {"seconds", report.seconds}}}};
}

IngestPart IngestPart::FromJson(const nlohmann::json& json, const std::string& what) {
  IngestPart part;
  try {
    part.directory = json.at("directory").get<std::string>();
    for (const auto& e : json.at("epochs")) part.epochs.push_back(EpochInfoFromJson(e));
    for (const auto& e : json.at("id_epochs")) part.id_epochs.push_back(EpochInfoFromJson(e));
    for (const auto& r : json.at("records")) part.records.push_back(EpochRecord::FromJson(r));
    const auto& report = json.at("report");
    for (const auto& r : report.at("epochs")) part.report.epochs.push_back(EpochReportFromJson(r));
    part.report.input_points = report.at("input_points").get<std::uint64_t>();
    part.report.read_points = report.at("read_points").get<std::uint64_t>();
    part.report.dropped_points = report.at("dropped_points").get<std::uint64_t>();
    part.report.store_bytes = report.at("store_bytes").get<std::uint64_t>();
    part.report.max_chunk_points = report.at("max_chunk_points").get<std::uint64_t>();
    part.report.memory_budget = report.at("memory_budget").get<std::uint64_t>();
    part.report.seconds = report.at("seconds").get<double>();
  } catch (const nlohmann::json::exception& e) {
    throw Error::Corruption(what, std::string("not an ingest part's description: ") + e.what());
  } catch (const Error& e) {
    if (e.kind() == ErrorKind::kInvalidArgument) throw Error::Corruption(what, e.what());
    throw;
  }
  return part;
}

}  // namespace octocosm
