// `octocosm render --reference`: the ground truth. Every particle of the
// original snapshot, read again from the files in double precision, drawn
// on the CPU by render/reference_rasterizer.h with the same camera and kernel
// as the GPU: no sampling, no quantization, no float, and nothing from a
// store.
//
// Smoothing lengths are the standard ones (ingest/smoothing_pass.h): the
// snapshot's own where it has them (GADGET's HSML, HDF5 SmoothingLength of
// SPH gas), else the radius holding each particle's k nearest neighbours
// (k = 32 by default), across the faces of a periodic box. That pass reads
// the snapshot one or more times in bounded memory; one more read draws. A
// store's full-detail rendering draws the same blobs when it was ingested
// with the same k (ingest's default).
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "ingest/smoothing_pass.h"
#include "ingest/snapshot/snapshot_source.h"
#include "render/image.h"
#include "render/render_view.h"
#include "render/selection_set.h"
#include "render/tone_map.h"

namespace octocosm {

struct ReferenceRenderOptions {
  ReadOptions read;            // as the snapshot was read by ingest (box size, types)
  // The smoothing lengths' pass: neighbours, use of the snapshot's own
  // lengths, memory budget, temporary directory. Its box is the snapshot's.
  SmoothingPassOptions smoothing;
  ColorMode color = ColorMode::kDensity;
  const SelectionSet* selection = nullptr;  // highlighted IDs, or null
  unsigned threads = 0;        // 0: all cores
};

struct ReferenceRenderStats {
  std::uint64_t particles = 0;
  std::uint64_t points_drawn = 0;  // between the near and far planes, in the first view
  SmoothingPassReport smoothing;
  double seconds = 0;              // the whole job, smoothing lengths included
};

// Renders snapshot `input`, one image per view from the same passes. Throws
// Error from the readers, from the smoothing pass, or InvalidArgument when a
// colour mode needs velocities the snapshot lacks.
std::vector<HdrImage> RenderReference(const std::string& input, std::span<const RenderView> views,
                                      const ReferenceRenderOptions& options, ReferenceRenderStats* stats = nullptr);
HdrImage RenderReference(const std::string& input, const RenderView& view, const ReferenceRenderOptions& options,
                         ReferenceRenderStats* stats = nullptr);

}  // namespace octocosm
