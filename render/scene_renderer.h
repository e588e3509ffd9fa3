// One frame of a dataset: the part of the renderer both front ends share
// (`octocosm render`, headless, and `octocosm view`, in a window).
//
// Per frame, on the CPU: the level of detail of each epoch drawn
// (query/lod_frontier.h: frustum culling, screen-space error, point budget),
// the blocks that needs, requested from the block cache in priority order
// (storage/prefetcher.h reads them on worker threads, only the columns the
// frame needs: query/column_reader.h ColumnSubsetSource), uploads of blocks
// that have arrived, and a draw plan (render/draw_plan.h) that lets loaded
// parents stand in for children still on their way. Everything else happens
// on the GPU (render/splat_renderer.h).
//
// Time. A frame shows a fractional epoch time = e + t. Where the store links
// epochs (particle IDs: displacements and, with velocities, the neighbours'
// velocities), both epoch e and e + 1 are drawn, e moved forward with weight
// 1 - t and e + 1 moved back with weight t along the same curve (linear, or
// cubic Hermite when velocities allow), so that each particle's position,
// size and colour pass smoothly from one epoch to the next, t = 0 and t = 1
// reproduce the epochs exactly, and mass is conserved in between. In a
// periodic box, displacements are minimal images and the moved positions are
// wrapped into the box, so a particle crossing a face passes out of one face
// and in at the opposite one. The point budget is shared between the two in
// proportion to their weights. Without links the nearest epoch is shown.
//
// Selections. The particles selected by ID are highlighted exactly at any
// level of detail: they are looked up through the ID index and drawn at full
// detail into the highlight channel (render/selection_overlay.h), while the
// level of detail draws the density and attributes of everything. Until that
// look-up has finished (streamed frames after a new selection or epoch) the
// points of the level of detail whose ID is selected are highlighted instead.
//
// Two ways to render: Complete() waits for every block the frame selects
// (headless pictures, tests, benchmarks); Stream() never waits for the disk
// (the viewer), drawing what is loaded and queueing the rest.
#pragma once

#include <cstdint>
#include <future>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "index/dataset.h"
#include "index/node_hierarchy.h"
#include "query/column_reader.h"
#include "query/lod_frontier.h"
#include "render/draw_plan.h"
#include "render/gpu_block.h"
#include "render/selection_overlay.h"
#include "render/selection_set.h"
#include "render/splat_renderer.h"
#include "storage/block_cache.h"
#include "storage/prefetcher.h"

namespace octocosm {

// A cluster error that reaches about 40 dB against the reference in the
// zoomed views of the render bench's 10^8 points from an eighth of their
// full-detail points (docs/ACCURACY.md section 6): where the viewer's
// overlay starts when cluster by cluster is switched on.
inline constexpr double kDefaultClusterError = 100;

struct SceneOptions {
  LodOptions lod;                       // pixel threshold, point budget
  // > 0, where the store links its clusters to their children's points
  // (Dataset::cluster_columns): the level of detail refines cluster by
  // cluster (query/cluster_frontier.h) with the threshold tau = cluster_error
  // x the epoch's mean particle mass, instead of node by node by the pixel
  // threshold; the point budget still holds. 0: node by node.
  double cluster_error = 0;
  ColorMode color = ColorMode::kDensity;
  Interpolation interpolation = Interpolation::kHermite;  // the best the store supports, at most this
  // Clusters drawn with their shapes (index/cluster_shape.h), where the store
  // has them; false: as round blobs of the same size.
  bool cluster_shapes = true;
  // Point sprites, or blobs added by compute shaders (render/compute_splatter.h).
  SplatPath splat_path = SplatPath::kAuto;
  double compute_radius = 4;  // pixels: the compute path adds larger blobs by a workgroup each
  std::size_t cpu_cache_bytes = std::size_t{1} << 30;     // blocks read from disk, in memory
  std::size_t gpu_cache_bytes = std::size_t{2} << 30;     // blocks on the GPU
  // Blocks read at once: 0 picks 2 for a local store and 32 for one on a
  // server, where each read waits a round trip.
  std::size_t io_threads = 0;
  // From a server, blocks near one another in a file are read with one
  // request (storage/prefetcher.h); false reads each alone (benchmarks).
  bool coalesce_reads = true;
  // Streaming only: most bytes uploaded to the GPU in one frame, so a frame
  // never stalls on a burst of arrivals.
  std::size_t upload_bytes_per_frame = std::size_t{64} << 20;
};

struct FrameStats {
  std::uint32_t epochs_drawn = 0;
  std::uint64_t nodes_selected = 0;
  std::uint64_t points_selected = 0;  // in the selected nodes
  // What was drawn (with stand-ins, while loading). Refining cluster by
  // cluster: the points of the draws, an upper bound of those the cut takes,
  // which a complete frame counts on the GPU (SplatRenderer::CutPointsCounted,
  // read by OffscreenRenderer::Render once the frame is finished).
  std::uint64_t points_drawn = 0;
  bool cluster_cut = false;           // the frame refined cluster by cluster
  std::uint64_t draws = 0;
  std::uint64_t stand_ins = 0;        // parent octants drawn for children not loaded yet
  std::uint64_t blocks_missing = 0;   // selected blocks not on the GPU yet
  std::uint64_t blocks_uploaded = 0;
  std::uint64_t bytes_uploaded = 0;
  std::uint64_t gpu_blocks = 0;       // resident on the GPU after the frame
  std::uint64_t gpu_bytes = 0;
  bool budget_reached = false;
  // The selected particles drawn at full detail over the level of detail
  // (highlight_exact), or false while they are looked up.
  bool highlight_exact = false;
  std::uint64_t points_highlighted = 0;
  Interpolation interpolation = Interpolation::kNone;
  double select_ms = 0, upload_ms = 0, draw_ms = 0;
};

class SceneRenderer {
 public:
  // `dataset` and `splat` must outlive the SceneRenderer; the GL context of
  // `splat` must be current whenever a method is called.
  SceneRenderer(const Dataset& dataset, SplatRenderer& splat, const SceneOptions& options);
  ~SceneRenderer();

  // Draws the frame into the SplatRenderer's accumulation buffer (the caller
  // measures and tone maps). `time` is clamped to [0, epochs - 1].
  // Complete: waits for every selected block; throws the Error of a block
  // that cannot be read. Stream: never waits for a read; a block that failed
  // is reported by last_error() and skipped.
  FrameStats Complete(const RenderView& view, double time);
  FrameStats Stream(const RenderView& view, double time, bool look_ahead);

  // Highlights these particle IDs (empty: none). Throws like SelectionSet.
  // The exact highlight needs the store's ID index; without it only points
  // of the level of detail can be highlighted.
  void SetSelection(std::span<const std::uint64_t> ids);
  std::size_t selection_size() const { return selection_ ? selection_->size() : 0; }
  void SetColorMode(ColorMode color);
  void SetLod(const LodOptions& lod) { options_.lod = lod; }
  void SetClusterError(double cluster_error) { options_.cluster_error = cluster_error; }
  // Whether frames refine cluster by cluster: asked for, and the store can.
  bool cluster_cut() const;
  void SetSplatPath(SplatPath path) { options_.splat_path = path; }
  const SceneOptions& options() const { return options_; }

  // The mass that the GPU's accumulation counts as 1 (render/splat_renderer.h).
  double mass_unit() const { return mass_unit_; }
  // The best interpolation available between `epoch` and the next.
  Interpolation InterpolationAvailable(std::uint32_t epoch) const;
  // The epoch's node hierarchy (its index, read once: a round trip from a
  // server), loaded now if no load has finished.
  const NodeHierarchy& hierarchy(std::uint32_t epoch);
  // Bytes read from the store so far, and the block cache's counters.
  ReadCounters disk_reads() const;
  CacheStats cache_stats() const;
  const std::string& last_error() const { return last_error_; }

 private:
  struct Copy {
    std::uint32_t epoch = 0;
    int direction = 1;  // +1 moving forward from this epoch, -1 moving back from it
    double weight = 1;
    LodFrontier frontier;
  };
  struct Resident {
    GpuBlock block;
    std::uint64_t last_frame = 0;
  };
  // A node of an epoch's hierarchy, by its index there.
  struct NodeRef {
    std::uint32_t epoch = 0;
    std::int32_t node = 0;
  };
  // The blocks of an epoch on the GPU, by node index: a frame looks each of
  // its tens of thousands of nodes up several times, in an array rather than
  // a hash table.
  struct EpochResidents {
    std::vector<std::unique_ptr<Resident>> by_node;
    std::size_t count = 0;
  };

  FrameStats Render(const RenderView& view, double time, bool complete, bool look_ahead);
  // The steps of Render, in order.
  std::vector<Copy> PlanCopies(double time, FrameStats& stats) const;
  void SelectFrontiers(const RenderView& view, std::vector<Copy>& copies, FrameStats& stats);
  LodFrontier SelectFrontier(const RenderView& view, std::uint32_t epoch, const LodOptions& lod);
  double CutThreshold(std::uint32_t epoch) const;
  // Submits the blocks wanted to the prefetcher and starts the selection
  // overlays; returns the blocks this frame draws.
  std::vector<NodeRef> RequestBlocks(const RenderView& view, const std::vector<Copy>& copies, bool complete,
                                     bool look_ahead);
  void UploadArrived(const std::vector<NodeRef>& needed, bool complete, FrameStats& stats);
  std::vector<const SelectionOverlay*> ReadyOverlays(const std::vector<Copy>& copies, bool complete, FrameStats& stats);
  void DrawCopies(const RenderView& view, const std::vector<Copy>& copies,
                  const std::vector<const SelectionOverlay*>& overlays, bool complete, FrameStats& stats);
  BlockId IdOf(NodeRef ref);
  Resident* FindResident(NodeRef ref);
  ColumnSet ColumnsFor(Interpolation interpolation, bool complete) const;
  void UseColumns(ColumnSet columns);
  const Resident* Upload(NodeRef ref, const Bytes& bytes);
  // What a block drawn by the cluster cut takes from its parent; false when
  // the parent is not on the GPU with its links.
  bool ParentOf(NodeRef ref, ClusterCutUpload& cut);
  void EvictGpuBlocks();
  // The selection overlay of `epoch` in the current columns, started if
  // need be; null when there is no selection to draw that way.
  SelectionOverlay* Overlay(std::uint32_t epoch);
  // Drops the overlays of epochs other than these.
  void KeepOverlays(std::span<const std::uint32_t> epochs);

  const Dataset& dataset_;
  SplatRenderer& splat_;
  SceneOptions options_;
  double mass_unit_ = 1;
  // An epoch's hierarchy, loaded on a thread of its own when a frame near
  // it in time starts it (StartLoadingNear), else by the first frame that
  // draws the epoch.
  struct HierarchySlot {
    std::unique_ptr<NodeHierarchy> loaded;
    std::future<NodeHierarchy> loading;
  };
  // Starts loading the hierarchy on a thread of its own, unless it is loaded
  // or loading.
  void StartLoading(std::uint32_t epoch);
  // The hierarchy if it is loaded (starting its load if none has started).
  const NodeHierarchy* HierarchyIfLoaded(std::uint32_t epoch);
  // Starts loading the hierarchies of the epochs next to those drawn (one
  // before, two after), so that stepping or playing through time does not
  // wait for their indexes.
  void StartLoadingNear(const std::vector<Copy>& copies);
  std::vector<HierarchySlot> hierarchies_;
  std::unique_ptr<SelectionSet> selection_;
  std::shared_ptr<const std::vector<std::uint64_t>> selected_ids_;
  std::vector<std::unique_ptr<SelectionOverlay>> overlays_;

  ColumnSet columns_ = 0;
  std::unique_ptr<ColumnSubsetSource> source_;
  std::unique_ptr<BlockCache> cache_;
  std::unique_ptr<Prefetcher> prefetcher_;
  ReadCounters retired_reads_;  // of sources replaced when the columns changed

  std::vector<EpochResidents> gpu_;  // by epoch
  std::size_t gpu_blocks_ = 0;
  std::size_t gpu_bytes_ = 0;
  std::uint64_t frame_ = 0;
  double cut_threshold_ = 0;  // this frame's, refining cluster by cluster
  std::string last_error_;
};

}  // namespace octocosm
