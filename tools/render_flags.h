// The flags `octocosm render` and `octocosm view` share, so that a picture
// from one can be reproduced with the other: the camera, the time, the level
// of detail, the colours and tone curve, the largest blob, the selection and
// the block cache.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "index/dataset.h"
#include "render/scene_renderer.h"
#include "render/tone_map.h"
#include "tools/camera_flags.h"

namespace CLI {
class App;
}

namespace octocosm {

struct SceneFlags {
  CameraFlags camera;
  double time = 0;  // a fractional epoch
  // The physical time of a cosmological store instead (--redshift,
  // --scale-factor): ResolveSceneFlags turns it into `time`.
  std::optional<double> redshift, scale_factor;
  // Level of detail.
  double error = 1;
  double cluster_error = 0;
  std::uint64_t budget = 0;
  bool full = false;
  // Colours and tone curve.
  std::string color = "density", colormap = "magma", attribute_colormap, color_range, curve = "log";
  double exposure = 0, percentile = 99.5, decades = 4, softening = 1e-3;
  double max_radius = kDefaultMaxBlobRadius;
  // How blobs are drawn (render/compute_splatter.h).
  std::string splat = "auto";
  double compute_radius = 4;
  // Highlighted particles.
  std::string select, select_box;
  std::string cache = "1G";
};

// Registers the camera flags (tools/camera_flags.h) and --time, --redshift,
// --scale-factor (one of the three), --error, --budget, --full, --color,
// --colormap, --attribute-colormap, --color-range, --curve, --exposure,
// --percentile, --decades, --softening, --max-radius, --splat,
// --compute-radius, --select, --select-box, --cache.
void AddSceneFlags(CLI::App& command, SceneFlags& flags);

// Sets `time` from --redshift or --scale-factor (Dataset::FractionalEpochAt),
// when one is given, and checks the flags that need the store. Throws
// Error::InvalidArgument for a physical time the store's epochs do not
// span or cannot place (naming the store), a --time outside the store's
// epochs, or an --error that is not > 0 (naming the flag).
void ResolveSceneFlags(SceneFlags& flags, const Dataset& dataset);

// The epoch a fractional time shows when it is not interpolated, and the one
// --select-box selects in.
std::uint32_t NearestEpoch(double time);

// Throws Error::InvalidArgument naming the flag.
ToneMapSettings ToneSettingsFrom(const SceneFlags& flags);
// Level of detail, colour mode and CPU block cache.
SceneOptions SceneOptionsFrom(const SceneFlags& flags);
// Throws Error::InvalidArgument when --max-radius exceeds what this OpenGL draws.
void CheckMaxRadius(const SceneFlags& flags, double gl_max_blob_radius);

// The IDs of --select (a file) and --select-box (particles in a box in
// `epoch`), concatenated; empty when neither is given. Throws like
// ReadIdFile and ParticleIdsInBox (Error::InvalidArgument when the store has
// no particle IDs).
std::vector<std::uint64_t> SelectedIds(const SceneFlags& flags, const Dataset& dataset, std::uint32_t epoch);

}  // namespace octocosm
