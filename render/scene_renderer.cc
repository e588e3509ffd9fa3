#include "render/scene_renderer.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "base/error.h"
#include "query/cluster_frontier.h"

namespace octocosm {
namespace {

// Hermite tangents come from the ingest's least-squares velocity scale; when
// velocities explain less than half of the displacements (relative residual
// above this), the curve would wander and linear paths are used instead.
constexpr double kHermiteMaxResidual = 0.5;

// Pixel sums of about 10^6 in float when all the mass is in view.
constexpr double kMassUnitDivisor = 1e6;

constexpr ColumnSet kCoreColumns = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                                   ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kType);

double Milliseconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since).count();
}

constexpr std::size_t kLocalIoThreads = 2;
constexpr std::size_t kRemoteIoThreads = 32;

}  // namespace

SceneRenderer::SceneRenderer(const Dataset& dataset, SplatRenderer& splat, const SceneOptions& options)
    : dataset_(dataset), splat_(splat), options_(options) {
  if (options_.io_threads == 0) {
    const bool remote = dataset.epoch_count() > 0 && dataset.store().page_file(0).remote();
    options_.io_threads = remote ? kRemoteIoThreads : kLocalIoThreads;
  }
  hierarchies_.resize(dataset.epoch_count());
  gpu_.resize(dataset.epoch_count());
  double mass = 0;
  for (std::uint32_t e = 0; e < dataset.epoch_count(); ++e) mass = std::max(mass, dataset.summary(e).mass.value_or(0));
  mass_unit_ = mass > 0 && std::isfinite(mass) ? mass / kMassUnitDivisor : 1;
}

SceneRenderer::~SceneRenderer() {
  // Workers first: they read through the cache, which reads through the source.
  prefetcher_.reset();
  cache_.reset();
}

const NodeHierarchy& SceneRenderer::hierarchy(std::uint32_t epoch) {
  HierarchySlot& slot = hierarchies_.at(epoch);
  if (!slot.loaded) {
    // A load started earlier is waited for (and its error thrown here).
    slot.loaded = std::make_unique<NodeHierarchy>(slot.loading.valid() ? slot.loading.get()
                                                                         : NodeHierarchy::Load(dataset_, epoch));
  }
  return *slot.loaded;
}

void SceneRenderer::StartLoading(std::uint32_t epoch) {
  HierarchySlot& slot = hierarchies_.at(epoch);
  if (slot.loaded || slot.loading.valid()) return;
  slot.loading = std::async(std::launch::async, [&dataset = dataset_, epoch] { return NodeHierarchy::Load(dataset, epoch); });
}

const NodeHierarchy* SceneRenderer::HierarchyIfLoaded(std::uint32_t epoch) {
  StartLoading(epoch);
  HierarchySlot& slot = hierarchies_[epoch];
  if (!slot.loaded && slot.loading.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return nullptr;
  return &hierarchy(epoch);
}

void SceneRenderer::StartLoadingNear(const std::vector<Copy>& copies) {
  if (copies.empty()) return;
  std::uint32_t first = copies.front().epoch, last = copies.front().epoch;
  for (const Copy& c : copies) {
    first = std::min(first, c.epoch);
    last = std::max(last, c.epoch);
  }
  const std::uint32_t final_epoch = dataset_.epoch_count() - 1;
  const std::uint32_t from = first > 0 ? first - 1 : 0;
  const std::uint32_t to = final_epoch - last >= 2 ? last + 2 : final_epoch;
  for (std::uint32_t e = from; e <= to; ++e) StartLoading(e);
}

Interpolation SceneRenderer::InterpolationAvailable(std::uint32_t epoch) const {
  if (epoch + 1 >= dataset_.epoch_count()) return Interpolation::kNone;
  const ColumnSet have = dataset_.columns();
  const ColumnSet linear = ColumnBit(ColumnId::kDisplacement) | ColumnBit(ColumnId::kPrevDisplacement);
  if ((have & linear) != linear) return Interpolation::kNone;
  const ColumnSet hermite =
      ColumnBit(ColumnId::kVelocity) | ColumnBit(ColumnId::kNextVelocity) | ColumnBit(ColumnId::kPrevVelocity);
  const std::optional<EpochLink>& link = dataset_.link_to_next(epoch);
  if ((have & hermite) == hermite && link && link->velocity_scale > 0 && link->fit_residual < kHermiteMaxResidual) {
    return Interpolation::kHermite;
  }
  return Interpolation::kLinear;
}

ColumnSet SceneRenderer::ColumnsFor(Interpolation interpolation, bool complete) const {
  ColumnSet c = kCoreColumns;
  if (ColorModeNeedsVelocity(options_.color)) c |= ColumnBit(ColumnId::kVelocity) | ColumnBit(ColumnId::kVelocityDispersion);
  if (options_.cluster_shapes) c |= ColumnBit(ColumnId::kShape);
  // The level of detail needs IDs only to highlight its own points, which a
  // complete frame never does when the selection can be looked up.
  if (selection_ && selection_->size() > 0 && !(complete && selected_ids_)) c |= ColumnBit(ColumnId::kId);
  if (interpolation != Interpolation::kNone) c |= ColumnBit(ColumnId::kDisplacement) | ColumnBit(ColumnId::kPrevDisplacement);
  if (interpolation == Interpolation::kHermite) {
    c |= ColumnBit(ColumnId::kVelocity) | ColumnBit(ColumnId::kNextVelocity) | ColumnBit(ColumnId::kPrevVelocity);
  }
  if (cluster_cut()) c |= kClusterLinkColumns;
  return c & (dataset_.columns() | kCoreColumns);
}

void SceneRenderer::UseColumns(ColumnSet columns) {
  if (columns == columns_ && cache_) return;
  if (source_) {
    const ReadCounters r = source_->counters();
    retired_reads_.blocks += r.blocks;
    retired_reads_.reads += r.reads;
    retired_reads_.bytes += r.bytes;
  }
  prefetcher_.reset();
  cache_.reset();
  // Blocks on the GPU hold the old columns: the next frames upload afresh.
  for (EpochResidents& epoch : gpu_) epoch = {};
  gpu_blocks_ = 0;
  gpu_bytes_ = 0;
  columns_ = columns;
  source_ = std::make_unique<ColumnSubsetSource>(dataset_, columns);
  cache_ = std::make_unique<BlockCache>(source_.get(), options_.cpu_cache_bytes);
  Prefetcher::Options prefetch;
  prefetch.workers = options_.io_threads;
  prefetch.coalesce_reads = options_.coalesce_reads;
  prefetcher_ = std::make_unique<Prefetcher>(*cache_, prefetch);
}

void SceneRenderer::SetSelection(std::span<const std::uint64_t> ids) {
  overlays_.clear();
  selected_ids_.reset();
  if (ids.empty()) {
    selection_.reset();
    return;
  }
  auto selection = std::make_unique<SelectionSet>(ids);
  selection->Upload();
  selection_ = std::move(selection);
  if (dataset_.has_id_index()) selected_ids_ = std::make_shared<const std::vector<std::uint64_t>>(ids.begin(), ids.end());
}

SelectionOverlay* SceneRenderer::Overlay(std::uint32_t epoch) {
  if (!selected_ids_) return nullptr;
  for (const auto& overlay : overlays_) {
    if (overlay->epoch() == epoch && overlay->columns() == columns_) return overlay.get();
  }
  overlays_.push_back(std::make_unique<SelectionOverlay>(dataset_, splat_.blocks(), epoch, selected_ids_, columns_));
  return overlays_.back().get();
}

void SceneRenderer::KeepOverlays(std::span<const std::uint32_t> epochs) {
  std::erase_if(overlays_, [&](const std::unique_ptr<SelectionOverlay>& overlay) {
    return overlay->columns() != columns_ || std::find(epochs.begin(), epochs.end(), overlay->epoch()) == epochs.end();
  });
}

void SceneRenderer::SetColorMode(ColorMode color) { options_.color = color; }

std::vector<SceneRenderer::Copy> SceneRenderer::PlanCopies(double time, FrameStats& stats) const {
  const std::uint32_t last = dataset_.epoch_count() - 1;
  time = std::clamp(std::isfinite(time) ? time : 0.0, 0.0, static_cast<double>(last));
  const auto epoch = static_cast<std::uint32_t>(std::min(std::floor(time), static_cast<double>(last)));
  const double t = time - epoch;
  const Interpolation available = InterpolationAvailable(epoch);
  const Interpolation interpolation =
      static_cast<int>(options_.interpolation) < static_cast<int>(available) ? options_.interpolation : available;
  stats.interpolation = t > 0 ? interpolation : Interpolation::kNone;
  if (t > 0 && interpolation != Interpolation::kNone) {
    return {Copy{epoch, +1, 1 - t, {}}, Copy{epoch + 1, -1, t, {}}};
  }
  return {Copy{t < 0.5 ? epoch : std::min(epoch + 1, last), +1, 1, {}}};
}

BlockId SceneRenderer::IdOf(NodeRef ref) { return BlockId{ref.epoch, hierarchy(ref.epoch).node(ref.node).key.value()}; }

SceneRenderer::Resident* SceneRenderer::FindResident(NodeRef ref) {
  const EpochResidents& epoch = gpu_[ref.epoch];
  const auto node = static_cast<std::size_t>(ref.node);
  return node < epoch.by_node.size() ? epoch.by_node[node].get() : nullptr;
}

const SceneRenderer::Resident* SceneRenderer::Upload(NodeRef ref, const Bytes& bytes) {
  const BlockId id = IdOf(ref);
  const NodeKey key = NodeKey::FromValue(id.key);
  const std::string where = dataset_.Where(id.epoch, key);
  const BlockHeader header = DecodeBlockHeader(bytes, key, where);
  if (header.block_size != bytes.size()) {
    throw Error::Corruption(where, "a cached block of " + std::to_string(bytes.size()) + " bytes says it has " +
                                       std::to_string(header.block_size));
  }
  ClusterCutUpload cut;
  const bool with_cut = cluster_cut() && ParentOf(ref, cut);
  GpuBlock block = GpuBlock::Upload(splat_.blocks(), bytes, header, dataset_.cube(id.epoch).NodeCubeOf(key), where,
                                    with_cut ? &cut : nullptr);
  auto resident = std::make_unique<Resident>(Resident{std::move(block), frame_});
  EpochResidents& epoch = gpu_[ref.epoch];
  if (epoch.by_node.empty()) epoch.by_node.resize(hierarchy(ref.epoch).nodes().size());
  std::unique_ptr<Resident>& slot = epoch.by_node[static_cast<std::size_t>(ref.node)];
  if (slot) {
    gpu_bytes_ -= slot->block.gpu_bytes();
  } else {
    ++epoch.count;
    ++gpu_blocks_;
  }
  gpu_bytes_ += resident->block.gpu_bytes();
  slot = std::move(resident);
  return slot.get();
}

bool SceneRenderer::ParentOf(NodeRef ref, ClusterCutUpload& cut) {
  const NodeHierarchy& h = hierarchy(ref.epoch);
  const std::int32_t parent = h.node(ref.node).parent;
  if (parent < 0) return true;  // the root
  const Resident* resident = FindResident({ref.epoch, parent});
  if (resident == nullptr || resident->block.links() == nullptr) return false;
  cut.parent = resident->block.links();
  cut.parent_node = resident->block.node();
  // The parent's links list its children's points octant by octant.
  cut.first_entry = 0;
  for (std::int32_t sibling : h.node(parent).children) {
    if (sibling == ref.node) break;
    if (sibling >= 0) cut.first_entry += h.node(sibling).entry.point_count;
  }
  return true;
}

void SceneRenderer::EvictGpuBlocks() {
  if (gpu_bytes_ <= options_.gpu_cache_bytes) return;
  struct Candidate {
    std::uint64_t last_frame;
    NodeRef ref;
  };
  std::vector<Candidate> candidates;
  for (std::uint32_t e = 0; e < gpu_.size(); ++e) {
    if (gpu_[e].count == 0) continue;
    const auto& by_node = gpu_[e].by_node;
    for (std::size_t node = 0; node < by_node.size(); ++node) {
      if (by_node[node] && by_node[node]->last_frame < frame_) {
        candidates.push_back({by_node[node]->last_frame, NodeRef{e, static_cast<std::int32_t>(node)}});
      }
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.last_frame < b.last_frame; });
  for (const Candidate& c : candidates) {
    if (gpu_bytes_ <= options_.gpu_cache_bytes) break;
    EpochResidents& epoch = gpu_[c.ref.epoch];
    std::unique_ptr<Resident>& slot = epoch.by_node[static_cast<std::size_t>(c.ref.node)];
    gpu_bytes_ -= slot->block.gpu_bytes();
    slot.reset();
    --epoch.count;
    --gpu_blocks_;
  }
}

FrameStats SceneRenderer::Complete(const RenderView& view, double time) { return Render(view, time, true, false); }

FrameStats SceneRenderer::Stream(const RenderView& view, double time, bool look_ahead) {
  return Render(view, time, false, look_ahead);
}

// A frame in named steps: which epochs and nodes, which blocks to read, what
// has arrived on the GPU, then the draws.
FrameStats SceneRenderer::Render(const RenderView& view, double time, bool complete, bool look_ahead) {
  FrameStats stats;
  auto clock = std::chrono::steady_clock::now();
  std::vector<Copy> copies = PlanCopies(time, stats);
  if (!complete) StartLoadingNear(copies);
  stats.cluster_cut = cluster_cut();
  cut_threshold_ = CutThreshold(copies[0].epoch);
  SelectFrontiers(view, copies, stats);
  UseColumns(ColumnsFor(stats.interpolation, complete));
  std::vector<NodeRef> needed = RequestBlocks(view, copies, complete, look_ahead);
  stats.select_ms = Milliseconds(clock);

  clock = std::chrono::steady_clock::now();
  UploadArrived(needed, complete, stats);
  // The cluster frontier reaches a level further through each level of
  // blocks that arrives: select again until nothing new is reached (a
  // streamed frame: nothing new has arrived). Where nothing was uploaded
  // (a warm frame) the same blocks would give the same frontier.
  double reselect_ms = 0;
  while (stats.cluster_cut && stats.blocks_uploaded > 0) {
    const std::uint64_t reached = stats.nodes_selected, uploaded = stats.blocks_uploaded;
    const auto select_clock = std::chrono::steady_clock::now();
    SelectFrontiers(view, copies, stats);
    needed = RequestBlocks(view, copies, complete, look_ahead);
    reselect_ms += Milliseconds(select_clock);
    UploadArrived(needed, complete, stats);
    if (stats.nodes_selected == reached && stats.blocks_uploaded == uploaded) break;
  }
  const std::vector<const SelectionOverlay*> overlays = ReadyOverlays(copies, complete, stats);
  stats.upload_ms = Milliseconds(clock) - reselect_ms;
  stats.select_ms += reselect_ms;

  clock = std::chrono::steady_clock::now();
  DrawCopies(view, copies, overlays, complete, stats);
  stats.draw_ms = Milliseconds(clock);

  EvictGpuBlocks();
  ++frame_;
  stats.gpu_blocks = gpu_blocks_;
  stats.gpu_bytes = gpu_bytes_;
  for (const auto& overlay : overlays_) stats.gpu_bytes += overlay->gpu_bytes();
  return stats;
}

bool SceneRenderer::cluster_cut() const {
  return options_.cluster_error > 0 && (dataset_.cluster_columns() & kClusterLinkColumns) == kClusterLinkColumns;
}

// The epochs of one interval share their particles: the first's mean mass
// gives the frame's threshold.
double SceneRenderer::CutThreshold(std::uint32_t epoch) const {
  const EpochSummary& summary = dataset_.summary(epoch);
  const double mean_mass = summary.points > 0 ? summary.mass.value_or(0) / static_cast<double>(summary.points) : 0;
  return std::isfinite(mean_mass) ? options_.cluster_error * mean_mass : 0;
}

LodFrontier SceneRenderer::SelectFrontier(const RenderView& view, std::uint32_t epoch, const LodOptions& lod) {
  if (!cluster_cut()) {
    const ScreenErrorView error_view{view.camera(), static_cast<double>(view.height()), lod.pixel_threshold};
    return SelectLodFrontier(hierarchy(epoch), dataset_.cube(epoch), error_view, lod);
  }
  ClusterLodOptions cut;
  cut.threshold = cut_threshold_;
  cut.focal_pixels = view.focal_pixels();
  cut.point_budget = lod.point_budget;
  cut.cull_margin = lod.cull_margin;
  return SelectClusterFrontier(hierarchy(epoch), dataset_.cube(epoch), view.camera(), cut,
                               [&](std::int32_t node) -> const NodeRefineBounds* {
                                 const Resident* r = FindResident({epoch, node});
                                 if (r == nullptr || !r->block.has_cut() || r->block.links() == nullptr) return nullptr;
                                 return &r->block.links()->refine_bounds();
                               });
}

void SceneRenderer::SelectFrontiers(const RenderView& view, std::vector<Copy>& copies, FrameStats& stats) {
  stats.nodes_selected = 0;
  stats.points_selected = 0;
  stats.budget_reached = false;
  for (Copy& copy : copies) {
    LodOptions lod = options_.lod;
    if (lod.point_budget > 0) {
      lod.point_budget = std::max<std::uint64_t>(1, static_cast<std::uint64_t>(std::ceil(static_cast<double>(lod.point_budget) * copy.weight)));
    }
    if (stats.interpolation != Interpolation::kNone) {
      const std::uint32_t from = copy.direction > 0 ? copy.epoch : copy.epoch - 1;
      const std::optional<EpochLink>& link = dataset_.link_to_next(from);
      lod.cull_margin = link ? link->max_excursion : 0;
    }
    copy.frontier = SelectFrontier(view, copy.epoch, lod);
    stats.nodes_selected += copy.frontier.selected.size();
    stats.points_selected += copy.frontier.points;
    stats.budget_reached |= copy.frontier.budget_reached;
  }
  stats.epochs_drawn = static_cast<std::uint32_t>(copies.size());
}

std::vector<SceneRenderer::NodeRef> SceneRenderer::RequestBlocks(const RenderView& view,
                                                                  const std::vector<Copy>& copies, bool complete,
                                                                  bool look_ahead) {
  // Blocks wanted, most important first: coarse before fine, the two copies
  // interleaved; then, when playing, the next interval's.
  std::vector<NodeRef> needed;  // what this frame draws
  std::size_t longest = 0;
  for (const Copy& c : copies) longest = std::max(longest, complete ? c.frontier.selected.size() : c.frontier.load_order.size());
  for (std::size_t i = 0; i < longest; ++i) {
    for (const Copy& c : copies) {
      const auto& order = complete ? c.frontier.selected : c.frontier.load_order;
      if (i < order.size()) needed.push_back(NodeRef{c.epoch, order[i]});
    }
  }
  // What is on the GPU already needs no reading (a warm frame submits nothing).
  std::vector<BlockId> wanted;
  for (const NodeRef& ref : needed) {
    if (FindResident(ref) == nullptr) wanted.push_back(IdOf(ref));
  }
  std::vector<std::uint32_t> overlay_epochs;
  for (const Copy& c : copies) overlay_epochs.push_back(c.epoch);
  if (look_ahead && !complete) {
    const std::uint32_t ahead = copies.back().epoch + 1;
    // Once the next interval's index has arrived: the frame does not wait for it.
    const NodeHierarchy* next_hierarchy = ahead < dataset_.epoch_count() ? HierarchyIfLoaded(ahead) : nullptr;
    if (next_hierarchy != nullptr) {
      overlay_epochs.push_back(ahead);
      const LodFrontier next = SelectFrontier(view, ahead, options_.lod);
      for (std::int32_t node : next.load_order) {
        if (FindResident({ahead, node}) == nullptr) wanted.push_back(IdOf({ahead, node}));
      }
    }
  }
  prefetcher_->Submit(wanted);
  KeepOverlays(overlay_epochs);
  for (const std::uint32_t epoch : overlay_epochs) Overlay(epoch);  // started early: the look-up reads leaves
  return needed;
}

// Uploads what has arrived (or, for a complete frame, waits for it).
void SceneRenderer::UploadArrived(const std::vector<NodeRef>& needed, bool complete, FrameStats& stats) {
  for (const NodeRef& ref : needed) {
    if (Resident* resident = FindResident(ref)) {
      resident->last_frame = frame_;
      continue;
    }
    const BlockId id = IdOf(ref);
    const Resident* uploaded = nullptr;
    if (complete) {
      const PinnedBlock block = cache_->Get(id);
      uploaded = Upload(ref, block.bytes());
    } else {
      if (stats.bytes_uploaded >= options_.upload_bytes_per_frame) continue;
      const PinnedBlock block = cache_->TryGet(id);
      if (!block) {
        if (const std::optional<Error> error = prefetcher_->LastError(id)) last_error_ = error->what();
        continue;
      }
      try {
        uploaded = Upload(ref, block.bytes());
      } catch (const Error& e) {
        last_error_ = e.what();
        cache_->Erase(id);
        continue;
      }
    }
    ++stats.blocks_uploaded;
    stats.bytes_uploaded += uploaded->block.gpu_bytes();
  }
}

// The selected particles at full detail, once looked up for every epoch drawn.
std::vector<const SelectionOverlay*> SceneRenderer::ReadyOverlays(const std::vector<Copy>& copies, bool complete,
                                                                  FrameStats& stats) {
  std::vector<const SelectionOverlay*> overlays;
  if (!selected_ids_) return overlays;
  for (const Copy& c : copies) {
    SelectionOverlay* overlay = Overlay(c.epoch);
    bool ready = false;
    if (complete) {
      ready = overlay->Ready(true);
    } else {
      try {
        ready = overlay->Ready(false);
      } catch (const Error& e) {
        last_error_ = e.what();
      }
    }
    if (ready) overlays.push_back(overlay);
  }
  stats.highlight_exact = overlays.size() == copies.size();
  return overlays;
}

// Resident blocks are scattered in memory and the draws visit them in the
// plan's order: each is asked for this many draws ahead, so that tens of
// thousands of blocks do not each wait for memory in turn.
constexpr std::size_t kDrawLookahead = 8;

void SceneRenderer::DrawCopies(const RenderView& view, const std::vector<Copy>& copies,
                               const std::vector<const SelectionOverlay*>& overlays, bool complete, FrameStats& stats) {
  FrameSettings settings;
  settings.color = options_.color;
  settings.path = options_.splat_path;
  settings.compute_radius = options_.compute_radius;
  settings.mass_unit = mass_unit_;
  const bool cut = stats.cluster_cut;
  if (cut) {
    settings.cut_threshold = cut_threshold_;
    settings.count_cut = complete;
  }
  settings.interpolation = stats.interpolation;
  settings.t = copies.size() == 2 ? copies[1].weight : 0;
  if (stats.interpolation == Interpolation::kHermite) settings.hermite_scale = dataset_.link_to_next(copies[0].epoch)->velocity_scale;
  if (const Cube& box = dataset_.cube(copies[0].epoch); box.periodic) {
    settings.box_origin = box.origin;
    settings.box_size = box.size;
  }
  splat_.BeginFrame(view, settings);
  const bool probe_ids = !stats.highlight_exact && (columns_ & ColumnBit(ColumnId::kId));
  splat_.SetSelection(probe_ids ? selection_.get() : nullptr);
  for (std::size_t copy = 0; copy < copies.size(); ++copy) {
    const Copy& c = copies[copy];
    const auto resident = [&](std::int32_t node) -> const Resident* { return FindResident({c.epoch, node}); };
    for (std::int32_t node : c.frontier.selected) stats.blocks_missing += resident(node) == nullptr;
    const auto loaded = [&](std::int32_t node) {
      const Resident* r = resident(node);
      return r != nullptr && (!cut || r->block.has_cut());
    };
    const auto offsets = [&](std::int32_t node) { return resident(node)->block.octant_offsets(); };
    const auto in_view = [&](std::int32_t node) {
      const GpuBlock& block = resident(node)->block;
      return c.frontier.culler.OctantsInView(block.node(), block.octant_reach());
    };
    const DrawPlan plan = cut ? PlanClusterDraws(hierarchy(c.epoch), c.frontier, loaded, offsets, in_view)
                              : PlanDraws(hierarchy(c.epoch), c.frontier, loaded, offsets, in_view);
    splat_.SetCopy(c.direction, c.weight);
    for (std::size_t i = 0; i < plan.ranges.size(); ++i) {
      if (i + kDrawLookahead < plan.ranges.size()) {
        // Both cache lines of a block's placement and cube.
        const auto* ahead = reinterpret_cast<const char*>(resident(plan.ranges[i + kDrawLookahead].node));
        __builtin_prefetch(ahead);
        __builtin_prefetch(ahead + 64);
      }
      const DrawRange& range = plan.ranges[i];
      splat_.Draw(resident(range.node)->block, range.first, range.count, range.cut);
    }
    stats.points_drawn += plan.points;
    stats.draws += plan.ranges.size();
    stats.stand_ins += plan.stand_ins;
    if (stats.highlight_exact) {
      splat_.SetHighlightOnly(true);
      for (const GpuBlock& block : overlays[copy]->blocks()) splat_.Draw(block, 0, block.point_count());
      splat_.SetHighlightOnly(false);
      stats.points_highlighted += overlays[copy]->points();
      stats.draws += overlays[copy]->blocks().size();
    }
  }
}

ReadCounters SceneRenderer::disk_reads() const {
  ReadCounters r = retired_reads_;
  if (source_) {
    const ReadCounters now = source_->counters();
    r.blocks += now.blocks;
    r.reads += now.reads;
    r.bytes += now.bytes;
  }
  return r;
}

CacheStats SceneRenderer::cache_stats() const { return cache_ ? cache_->Stats() : CacheStats{}; }

}  // namespace octocosm
