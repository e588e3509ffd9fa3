#include "render/offscreen_renderer.h"

#include <chrono>

namespace octocosm {

OffscreenRenderer::OffscreenRenderer(const Dataset& dataset, HeadlessBackend backend, const SceneOptions& options)
    : context_(CreateHeadlessContext(backend)),
      splat_(std::make_unique<SplatRenderer>()),
      scene_(std::make_unique<SceneRenderer>(dataset, *splat_, options)),
      description_(CurrentGlDescription()) {}

OffscreenRenderer::~OffscreenRenderer() {
  // GL objects go while their context is current.
  context_->MakeCurrent();
  scene_.reset();
  splat_.reset();
}

Picture OffscreenRenderer::Render(const RenderView& view, double time, const ToneMapSettings& tone, bool read_hdr,
                                  ExposureSmoother* smoother, double elapsed) {
  const auto start = std::chrono::steady_clock::now();
  // Another renderer on this thread (a second store, from Python) may have
  // made its own context current since.
  context_->MakeCurrent();
  Picture picture;
  scene_->SetColorMode(tone.color);
  picture.stats = scene_->Complete(view, time);
  const ImageStatistics statistics =
      statistics_timing_ == StatisticsTiming::kLatest ? splat_->MeasureLate() : splat_->Measure();
  const double exposure =
      smoother && tone.exposure == 0 ? smoother->Update(AutomaticExposure(tone, statistics), elapsed) : 0.0;
  picture.tone = ResolveToneMap(tone, statistics, exposure);
  splat_->ToneMapToImage(picture.tone);
  splat_->Finish();
  const auto drawn = std::chrono::steady_clock::now();
  if (picture.stats.cluster_cut) picture.stats.points_drawn = splat_->CutPointsCounted();  // finished: no wait
  picture.rgb = splat_->ReadDisplay();
  if (read_hdr) picture.hdr = splat_->ReadHdr();
  const auto end = std::chrono::steady_clock::now();
  picture.readback_ms = std::chrono::duration<double, std::milli>(end - drawn).count();
  picture.frame_seconds = std::chrono::duration<double>(drawn - start).count();
  picture.seconds = std::chrono::duration<double>(end - start).count();
  picture.gpu_times = splat_->LatestGpuTimes(true);  // finished: the picture was read back
  return picture;
}

}  // namespace octocosm
