// Pictures of a dataset without a window: a headless GL context
// (render/gl_context.h), the splat renderer and the scene renderer, used by
// `octocosm render`, the tests and the benchmarks. One frame is drawn
// completely (every selected block loaded), measured, tone mapped on the GPU
// and read back.
#pragma once

#include <memory>
#include <optional>

#include "index/dataset.h"
#include "render/gl_context.h"
#include "render/scene_renderer.h"
#include "render/splat_renderer.h"
#include "render/tone_map.h"

namespace octocosm {

struct Picture {
  RgbImage rgb;                  // tone mapped on the GPU
  std::optional<HdrImage> hdr;   // the accumulation, when asked for
  FrameStats stats;
  ToneMapParameters tone;        // what the tone mapping used (the exposure, resolved)
  double seconds = 0;            // the whole frame, GPU work and reading the picture back included
  double frame_seconds = 0;      // the frame drawn and tone mapped (the GPU done), before the read-back
  // Where the time went besides stats' CPU times (select, upload, draw
  // calls): the GPU's stages, and reading the picture back.
  std::optional<GpuStageTimes> gpu_times;
  double readback_ms = 0;
};

// Which image statistics set a frame's tone mapping.
enum class StatisticsTiming {
  kThisFrame,  // this frame's, waited for: what one picture needs
  kLatest,     // the newest the GPU has finished, as a render loop takes them
               // (usually the frame before; this frame's where there is none):
               // no wait inside the frame
};

class OffscreenRenderer {
 public:
  // Creates the context on this thread; every call must come from it.
  OffscreenRenderer(const Dataset& dataset, HeadlessBackend backend, const SceneOptions& options);
  ~OffscreenRenderer();

  // Renders `view` at fractional epoch `time`. With a `smoother` (frames of a
  // movie, `elapsed` seconds apart) an automatic exposure is smoothed over
  // the frames instead of taken from this frame alone.
  Picture Render(const RenderView& view, double time, const ToneMapSettings& tone, bool read_hdr,
                 ExposureSmoother* smoother = nullptr, double elapsed = 0);
  // kThisFrame unless set. kLatest suits frames that repeat or continue the
  // one before (a benchmark's warm frames, a movie's).
  void SetStatisticsTiming(StatisticsTiming timing) { statistics_timing_ = timing; }

  SceneRenderer& scene() { return *scene_; }
  SplatRenderer& splat() { return *splat_; }
  // The largest blob radius the GL implementation draws.
  double max_blob_radius() const { return splat_->max_blob_radius(); }
  std::string description() const { return description_; }

 private:
  std::unique_ptr<GlContext> context_;
  std::unique_ptr<SplatRenderer> splat_;
  std::unique_ptr<SceneRenderer> scene_;
  std::string description_;
  StatisticsTiming statistics_timing_ = StatisticsTiming::kThisFrame;
};

}  // namespace octocosm
