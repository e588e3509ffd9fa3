#include "tools/reference_render.h"

#include <chrono>
#include <memory>
#include <vector>

#include "base/error.h"
#include "base/parallel_for.h"
#include "index/cube.h"
#include "render/reference_rasterizer.h"

namespace octocosm {

std::vector<HdrImage> RenderReference(const std::string& input, std::span<const RenderView> views,
                                      const ReferenceRenderOptions& options, ReferenceRenderStats* stats) {
  if (views.empty()) return {};
  const auto start = std::chrono::steady_clock::now();
  const int threads = ResolveThreadCount(static_cast<int>(options.threads));
  std::unique_ptr<ParticleSource> source = OpenSnapshot(input, options.read);
  const SnapshotHeader& header = source->header();
  if (ColorModeNeedsVelocity(options.color) && !header.has_velocity) {
    throw Error::InvalidArgument("colour mode '" + std::string(ColorModeName(options.color)) + "' needs velocities, and " +
                                 input + " has none");
  }

  // Positions are drawn where ingest stores them: wrapped into a periodic box.
  const bool periodic = header.box_size > 0;
  const Cube box{{0, 0, 0}, periodic ? header.box_size : 1.0, periodic};
  SmoothingPassOptions smoothing = options.smoothing;
  smoothing.box_size = header.box_size;
  smoothing.box_origin = box.origin;
  if (smoothing.threads == 0) smoothing.threads = options.threads;
  SmoothingPassReport smoothing_report;
  const std::unique_ptr<SmoothingLengthTable> lengths = ComputeSmoothingLengths(*source, smoothing, &smoothing_report);

  // One rasterizer per view and thread; each thread takes a contiguous range
  // of every chunk.
  std::vector<std::vector<ReferenceRasterizer>> rasterizers(static_cast<std::size_t>(threads));
  for (auto& per_thread : rasterizers) {
    for (const RenderView& view : views) per_thread.emplace_back(view);
  }
  source->Rewind();
  ParticleChunk chunk;
  std::uint64_t first = 0;
  while (source->Next(chunk)) {
    const std::size_t n = chunk.size();
    // One item per thread, so that each part draws into its own rasterizers.
    ParallelFor(static_cast<std::size_t>(threads), threads, [&](std::size_t part, std::size_t) {
      auto& mine = rasterizers[part];
      const std::size_t end = n * (part + 1) / static_cast<std::size_t>(threads);
      for (std::size_t i = n * part / static_cast<std::size_t>(threads); i < end; ++i) {
        double p[3] = {chunk.position[3 * i], chunk.position[3 * i + 1], chunk.position[3 * i + 2]};
        box.Wrap(p);
        const double h = (*lengths)[first + i];
        const bool selected = options.selection && chunk.has_id() && options.selection->Contains(chunk.id[i]);
        for (std::size_t v = 0; v < views.size(); ++v) {
          const double a = options.color == ColorMode::kDensity
                               ? 0.0
                               : PointAttribute(options.color, chunk.has_velocity() ? &chunk.velocity[3 * i] : nullptr,
                                                chunk.type[i], views[v]);
          mine[v].Add(p, chunk.mass[i], h, a, selected);
        }
      }
    }, /*min_items_per_thread=*/1);
    first += n;
  }
  std::vector<HdrImage> images;
  for (std::size_t v = 0; v < views.size(); ++v) {
    for (std::size_t t = 1; t < rasterizers.size(); ++t) rasterizers[0][v].Merge(rasterizers[t][v]);
    images.push_back(rasterizers[0][v].image());
  }
  if (stats) {
    stats->particles = first;
    stats->points_drawn = rasterizers[0][0].points_drawn();  // merged: every thread's
    stats->smoothing = smoothing_report;
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return images;
}

HdrImage RenderReference(const std::string& input, const RenderView& view, const ReferenceRenderOptions& options,
                         ReferenceRenderStats* stats) {
  return std::move(RenderReference(input, std::span<const RenderView>(&view, 1), options, stats)[0]);
}

}  // namespace octocosm
