// `octocosm render --reference`: the ground truth. Every particle of the
// original snapshot, read again from the files in double precision, drawn
// on the CPU by render/reference_rasterizer.h with the same camera and kernel
// as the GPU: no sampling, no quantization, no float.
//
// Smoothing lengths. A particle has no size in a snapshot; octocosm defines
// it at ingest from the particle's leaf (index/sampler.h, step 5 with the
// particle's own mass: h = eta * (m / rho)^(1/3), rho from the leaf's fine
// density grid). The reference uses that same definition, computed here from
// the snapshot's own positions and masses: the store supplies only the leaf
// partition (which leaf holds each position) and the grid resolution. Two
// passes over the snapshot: the first sums the mass in every occupied fine
// cell (sorted (cell, mass) pairs: about 16 bytes of memory per particle),
// the second draws.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "index/dataset.h"
#include "render/image.h"
#include "render/render_view.h"
#include "render/selection_set.h"
#include "render/tone_map.h"
#include "tools/snapshot/snapshot_source.h"

namespace octocosm {

struct ReferenceRenderOptions {
  ReadOptions read;            // as the snapshot was read by ingest
  ColorMode color = ColorMode::kDensity;
  const SelectionSet* selection = nullptr;  // highlighted IDs, or null
  unsigned threads = 0;        // 0: all cores
};

struct ReferenceRenderStats {
  std::uint64_t particles = 0;
  std::uint64_t points_drawn = 0;  // between the near and far planes
  double seconds = 0;
};

// Renders snapshot `input` as epoch `epoch` of `dataset`, one image per
// view from the same two passes. Throws Error::BadInput (naming the
// snapshot) when a particle lies where the store has no leaf, i.e. the
// snapshot is not the one the epoch was ingested from, or was read with
// other flags; Error from the readers otherwise. `stats` counts points drawn
// in the first view.
std::vector<HdrImage> RenderReference(const Dataset& dataset, std::uint32_t epoch, const std::string& input,
                                      std::span<const RenderView> views, const ReferenceRenderOptions& options,
                                      ReferenceRenderStats* stats = nullptr);
HdrImage RenderReference(const Dataset& dataset, std::uint32_t epoch, const std::string& input, const RenderView& view,
                         const ReferenceRenderOptions& options, ReferenceRenderStats* stats = nullptr);

}  // namespace octocosm
