// The GPU half of the renderer: blobs into a float accumulation buffer, image
// statistics, tone mapping, read-back. The CPU hands it blocks and ranges of
// points (render/scene_renderer.h decides which); the shaders decode, move
// (time interpolation), project, size, weigh, highlight and accumulate every
// point. Needs a current OpenGL 4.5 core context (render/gl_context.h) for
// its whole life.
//
// Accumulation: an RGBA32F texture (render/image.h gives the channels) larger
// than the image by a guard margin on every side (render/splat_kernel.h
// GuardMargin), because GL discards a point whose centre is outside the
// viewport; blending adds, so the result does not depend on drawing order
// beyond float rounding. Weights are divided by a mass unit on the GPU so
// that pixel sums stay in a comfortable float range whatever the simulation's
// mass units; every read-back multiplies it out again.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "render/compute_splatter.h"
#include "render/gl_objects.h"
#include "render/gpu_block.h"
#include "render/gpu_stage_timer.h"
#include "render/image.h"
#include "render/render_view.h"
#include "render/selection_set.h"
#include "render/tone_map.h"

namespace octocosm {

// How points move between two epochs (shaders/splat_vert.glsl).
enum class Interpolation {
  kNone,     // drawn where they are
  kLinear,   // p + t d (forward copy), p' + (1 - t) d' (backward copy)
  kHermite,  // the cubic Hermite curve with tangents scale * v at both ends
};

// How blobs reach the accumulation buffer (render/compute_splatter.h).
enum class SplatPath {
  kRaster,   // every point a point sprite, blended
  kCompute,  // blobs added by compute shaders: a thread a small blob, a workgroup a large one
  kAuto,     // compute on a hardware GPU that can (SplatRenderer::compute_preferred), else raster
};

// "raster", "compute", "auto"; and back (throws Error::InvalidArgument).
const char* SplatPathName(SplatPath path);
SplatPath ParseSplatPath(const std::string& name);

struct FrameSettings {
  ColorMode color = ColorMode::kDensity;
  SplatPath path = SplatPath::kAuto;
  double compute_radius = 4;  // pixels: the compute path adds larger blobs by a workgroup each
  double mass_unit = 1;  // > 0: the GPU accumulates mass / mass_unit
  Interpolation interpolation = Interpolation::kNone;
  double t = 0;              // in [0, 1]
  double hermite_scale = 0;  // velocity -> displacement per interval (the ingest's fit)
  // A periodic box (box_size > 0): points moved by interpolation are drawn
  // wrapped into [box_origin, box_origin + box_size) on every axis, so that a
  // particle crossing a face appears at the opposite face, inside the box.
  std::array<double, 3> box_origin{};
  double box_size = 0;  // 0: not periodic
  // The cluster cut (render/cluster_links.h): the threshold tau (mass units,
  // >= 0) of the draws that take part in it, and whether to count the points
  // it takes (CutPointsCounted).
  double cut_threshold = 0;
  bool count_cut = false;
};

class SplatRenderer {
 public:
  SplatRenderer();
  SplatRenderer(const SplatRenderer&) = delete;
  SplatRenderer& operator=(const SplatRenderer&) = delete;
  ~SplatRenderer();

  // The largest blob radius this GL implementation can draw (its point size limit).
  double max_blob_radius() const { return max_blob_radius_; }
  // Whether this GL can take the compute path (render/compute_splatter.h).
  bool compute_supported() const { return compute_supported_; }
  // The path the current (or last) frame takes: kRaster or kCompute. A frame
  // asking for kCompute takes the raster path where the compute path cannot
  // hold its image (one storage buffer's size) or the GL lacks it.
  SplatPath frame_path() const { return compute_frame_ ? SplatPath::kCompute : SplatPath::kRaster; }
  // Room for so many blobs above the compute radius a dispatch; tests shrink it.
  void SetLargeBlobCapacity(std::uint32_t blobs);

  // Starts a frame: sizes the accumulation buffer for the view and clears it.
  // Throws Error::InvalidArgument when the view's largest blob radius exceeds
  // max_blob_radius() or a setting is out of range.
  void BeginFrame(const RenderView& view, const FrameSettings& settings);
  // Which copy the next draws are, when interpolating: +1 the earlier epoch
  // moving forward, -1 the later epoch moving back; `weight` scales their mass.
  void SetCopy(int direction, double weight);
  // Highlights the points whose ID is in `selection` (null: none). The
  // selection must be uploaded and outlive the frame's draws.
  void SetSelection(const SelectionSet* selection);
  // While on, the points drawn are selected particles drawn over the frame:
  // they add their mass to the highlight channel only (the density and
  // attribute channels already hold them, in whatever level of detail drew
  // the rest). Off at BeginFrame.
  void SetHighlightOnly(bool on);
  // Where blocks are uploaded for drawing; it outlives every GpuBlock in it
  // as long as their owners are destroyed before this renderer.
  GpuBlockArena& blocks() { return arena_; }
  // Draws points [first, first + count) of `block`: queued, and issued with
  // the other draws queued since, as one multi-draw per pool, before the next
  // change of settings, measure, tone map or read-back.
  // Throws Error::InvalidArgument for a cut role on a block without the
  // cut's entries.
  void Draw(const GpuBlock& block, std::uint32_t first, std::uint32_t count, CutRole cut = CutRole::kNone);
  // The points the cluster cut took in this frame's draws so far (with
  // FrameSettings::count_cut; highlight-only draws not counted). Waits for
  // the GPU.
  std::uint64_t CutPointsCounted();

  // Starts measuring the frame so far (ImageStatistics: two compute passes
  // into an 8 KiB buffer, copied where the CPU reads it) without waiting for
  // the GPU. A render loop takes LatestStatistics(), usually a
  // frame late, and never stalls on a read-back.
  void StartMeasure();
  // The statistics of the newest measure the GPU has finished, without
  // waiting (`wait`: of the newest started, waiting for it); empty before
  // the first.
  std::optional<ImageStatistics> LatestStatistics(bool wait = false);
  // StartMeasure, waiting for the result: the statistics of the frame so far.
  ImageStatistics Measure();
  // StartMeasure, then the newest statistics the GPU has finished (a render
  // loop's way: usually a frame or two old); this frame's, waited for, when
  // none has finished yet.
  ImageStatistics MeasureLate();
  // GPU time of the stages of the newest frame the GPU has finished (frame
  // start to measure, measure, tone map); `wait`: of the last frame drawn,
  // waiting for it.
  std::optional<GpuStageTimes> LatestGpuTimes(bool wait) { return timer_.Latest(wait); }
  // Tone maps the frame into the internal display image (ReadDisplay), or
  // into the viewport at (x, y) of the framebuffer bound for drawing.
  void ToneMapToImage(const ToneMapParameters& parameters);
  void ToneMapToViewport(const ToneMapParameters& parameters, int x, int y);

  HdrImage ReadHdr();
  RgbImage ReadDisplay();
  // Waits until the GPU has finished every command (for timing).
  void Finish();

 private:
  void UploadFrameUniforms();
  // Issues the queued draws.
  void Flush();
  void FlushRaster();
  void FlushCompute();
  // The columns the compute shader reads for the draws of `pool` this frame.
  ComputeColumns ComputeColumnsOf(std::uint32_t pool) const;
  // Adds what the compute path accumulated into the accumulation texture.
  void Resolve();
  void ToneMap(const ToneMapParameters& parameters, int x, int y);

  GlProgram splat_;
  GlProgram tone_map_;
  GlProgram statistics_;
  GlVertexArray empty_vao_;
  GlBuffer frame_uniforms_;
  // The statistics' passes add into this buffer in GPU memory (their
  // atomics would cross the bus to a buffer the CPU maps), then copy it into
  // a mapped one. Measures in flight: the GPU writes one mapped buffer while
  // the CPU may still read an older one.
  GlBuffer statistics_work_;
  struct PendingStatistics {
    GlBuffer buffer;
    const std::uint32_t* words = nullptr;  // mapped for good (persistent, coherent)
    GLsync fence = nullptr;                // set when a measure was started; null once collected
    ColorMode color = ColorMode::kDensity;
    std::uint64_t serial = 0;
  };
  // Reads `pending` once the GPU has written it (waiting when `wait`) into
  // latest_statistics_ unless a newer one is there; false when not yet written.
  bool Collect(PendingStatistics& pending, bool wait);
  std::array<PendingStatistics, 3> measures_;
  std::size_t measure_next_ = 0;
  std::uint64_t measures_started_ = 0;    // serial of the newest measure started
  std::uint64_t measures_collected_ = 0;  // serial of latest_statistics_
  std::optional<ImageStatistics> latest_statistics_;
  GpuStageTimer timer_;
  GlBuffer no_selection_;
  GlBuffer cut_counter_;  // atomic counter binding 0: the points the cut took
  // A texture and the framebuffer that draws into it.
  struct RenderTarget {
    GlTexture texture;
    GlFramebuffer framebuffer;
    int width = 0, height = 0;
  };
  // (Re)allocates `target` as `format` at width x height unless it already is.
  static void Allocate(RenderTarget& target, GLenum format, int width, int height, const char* what);
  RenderTarget accumulation_;  // RGBA32F: the image and a guard margin around it
  RenderTarget display_;       // RGBA8: the tone-mapped image
  int margin_ = 0;
  double max_blob_radius_ = 0;

  // The current frame.
  bool in_frame_ = false;
  int width_ = 0, height_ = 0;
  std::array<double, 3> camera_position_{};
  FrameSettings settings_;
  int copy_direction_ = 1;
  double copy_weight_ = 1;
  bool selection_on_ = false;
  bool highlight_only_ = false;
  bool draw_state_set_ = false;  // the splat pass's GL state is bound (reset by anything else)
  struct FrameUniforms {
    float right[4], up[4], forward[4], viewport[4], limits[4];
    std::int32_t modes[4];
    float time[4];
    std::int32_t wrap[4];
    float cut[4];
  } uniforms_{};

  // The frame's draws ("Draws" and the indirect commands of
  // shaders/splat_vert.glsl); each command's base instance is its record.
  struct DrawRecord {
    float origin[4], box_low[4], box_high[4], origin_below[4], origin_above[4];
    std::uint32_t block[4];
    float parent_origin[4];
    std::uint32_t cut[4];
  };
  static_assert(sizeof(DrawRecord) == 128);
  struct DrawCommand {
    GLuint count, instance_count, first, base_instance;
  };
  // A draw queued: its record (all but block.yzw) and points of its pool.
  struct QueuedDraw {
    DrawRecord record;
    std::uint32_t first, count;
  };
  GpuBlockArena arena_;
  std::vector<DrawRecord> records_;                 // this frame's, in order
  std::size_t records_uploaded_ = 0;
  std::vector<std::vector<QueuedDraw>> queued_;     // by pool
  std::vector<std::vector<DrawCommand>> commands_;  // by pool, while flushing
  // Uploads records_ past records_uploaded_, into a larger buffer if need be.
  void UploadRecords();
  GlBuffer records_buffer_;
  std::size_t records_capacity_ = 0;
  GlBuffer commands_buffer_;
  std::size_t commands_capacity_ = 0;
  std::size_t commands_used_ = 0;  // this frame

  bool compute_supported_ = false;
  // Whether SplatPath::kAuto takes the compute path: where it is supported
  // and the GL is not a software rasterizer (llvmpipe blends sprites 1.5-3x
  // faster than it runs the compute path's atomics; a GPU, whose graphics
  // units are few, the other way round).
  bool compute_preferred_ = false;
  std::unique_ptr<ComputeSplatter> compute_;  // made on the first frame that takes the compute path
  bool compute_frame_ = false;                // this frame takes it
};

}  // namespace octocosm
