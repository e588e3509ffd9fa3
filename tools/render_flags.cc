#include "tools/render_flags.h"

#include <cmath>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "query/particle_lookup.h"
#include "tools/cli_util.h"
#include "tools/cmd_query.h"

namespace octocosm {

void AddSceneFlags(CLI::App& cmd, SceneFlags& f) {
  AddCameraFlags(cmd, f.camera);
  CLI::Option* time =
      cmd.add_option("--time", f.time, "epoch to show; a fraction interpolates between two epochs (e.g. 2.25)")->default_val(0);
  CLI::Option* redshift = cmd.add_option(
      "--redshift", f.redshift,
      "redshift to show, instead of --time (cosmological stores): the epochs on either side, interpolated linearly in "
      "the scale factor");
  CLI::Option* scale_factor =
      cmd.add_option("--scale-factor", f.scale_factor, "scale factor a = 1/(1+z) to show, instead of --time; as --redshift");
  redshift->excludes(time);
  scale_factor->excludes(time);
  scale_factor->excludes(redshift);
  cmd.add_option("--error", f.error, "level of detail: refine while points are more than this many pixels apart")->default_val(1);
  cmd.add_option("--cluster-error", f.cluster_error,
                 "level of detail cluster by cluster, where the store links its clusters: draw a cluster where its "
                 "error bound (its mass times its blob's area on screen, times its radius once larger than a pixel) "
                 "is at most this many mean particle masses (about 100 for 40 dB), instead of refining by --error "
                 "(0: by --error)")
      ->default_val(0);
  cmd.add_option("--budget", f.budget, "most points to draw (0: no limit)")->default_val(0);
  cmd.add_flag("--full", f.full, "draw every particle (every leaf in view), ignoring --error and --budget");
  cmd.add_option("--color", f.color, "colour: density, speed, los-velocity, dispersion (line-of-sight velocity dispersion) or type")
      ->default_val("density");
  cmd.add_option("--colormap", f.colormap, "colour map of density: magma, inferno, viridis, coolwarm, gray")->default_val("magma");
  cmd.add_option("--attribute-colormap", f.attribute_colormap, "colour map of the attribute (default: viridis; coolwarm for los-velocity)");
  cmd.add_option("--color-range", f.color_range, "attribute values at the ends of its colour map, low,high (default: 1st-99th percentile)");
  cmd.add_option("--curve", f.curve, "tone curve: log or asinh")->default_val("log");
  cmd.add_option("--exposure", f.exposure, "mass per pixel shown at full brightness (0: automatic)")->default_val(0);
  cmd.add_option("--percentile", f.percentile, "automatic exposure: this percentile of the lit pixels' mass")->default_val(99.5);
  cmd.add_option("--decades", f.decades, "log curve: decades of density below the exposure that stay visible")->default_val(4);
  cmd.add_option("--softening", f.softening, "asinh curve: linear below exposure * softening")->default_val(1e-3);
  cmd.add_option("--max-radius", f.max_radius, "largest blob radius, pixels")->default_val(kDefaultMaxBlobRadius);
  cmd.add_option("--splat", f.splat,
                 "how blobs are drawn: raster (point sprites, blended) or compute (added by compute shaders with float "
                 "atomics: a thread a small blob, a workgroup a large one); auto: compute on a GPU that has float atomics, "
                 "raster on software OpenGL (llvmpipe)")
      ->default_val("auto");
  cmd.add_option("--compute-radius", f.compute_radius, "compute path: blobs up to this radius (pixels) are added by one thread, larger ones by a workgroup")
      ->default_val(4);
  cmd.add_option("--select", f.select, "highlight the particle IDs listed in this file (one per line)");
  cmd.add_option("--select-box", f.select_box, "highlight the particles in the box x0,y0,z0,x1,y1,z1 (in the epoch nearest the time shown)");
  cmd.add_option("--cache", f.cache, "memory for blocks read from the store")->default_val("1G");
}

void ResolveSceneFlags(SceneFlags& f, const Dataset& dataset) {
  if (f.redshift) f.time = dataset.FractionalEpochAt({PhysicalTime::Scale::kRedshift, *f.redshift});
  if (f.scale_factor) f.time = dataset.FractionalEpochAt({PhysicalTime::Scale::kScaleFactor, *f.scale_factor});
  if (!(f.time >= 0 && f.time <= dataset.epoch_count() - 1.0)) {
    throw Error::InvalidArgument("--time " + std::to_string(f.time) + " is outside the store's epochs 0.." +
                                 std::to_string(dataset.epoch_count() - 1));
  }
  if (!(f.error > 0)) throw Error::InvalidArgument("--error must be > 0 pixels");
  if (f.cluster_error > 0 && (dataset.cluster_columns() & kClusterLinkColumns) != kClusterLinkColumns) {
    throw Error::InvalidArgument("--cluster-error: the store " + dataset.store().directory() +
                                 " does not link its clusters to their children's points (ingested with --coarse "
                                 "sample, or before octocosm wrote the links); use --error, or ingest it again");
  }
}

std::uint32_t NearestEpoch(double time) { return static_cast<std::uint32_t>(std::lround(time)); }

ToneMapSettings ToneSettingsFrom(const SceneFlags& f) {
  ToneMapSettings tone;
  tone.curve = ParseToneCurve(f.curve);
  tone.exposure = f.exposure;
  tone.auto_percentile = f.percentile;
  tone.log_decades = f.decades;
  tone.asinh_softening = f.softening;
  tone.density_map = ParseColorMap(f.colormap);
  tone.color = ParseColorMode(f.color);
  tone.attribute_map =
      !f.attribute_colormap.empty() ? ParseColorMap(f.attribute_colormap) : DefaultAttributeColorMap(tone.color);
  if (!f.color_range.empty()) {
    const std::vector<double> v = ParseNumberList(f.color_range, "--color-range");
    if (v.size() != 2 || !(v[0] < v[1])) throw Error::InvalidArgument("--color-range: expected two numbers low,high with low < high");
    tone.attribute_low = v[0];
    tone.attribute_high = v[1];
  }
  tone.Validate();
  return tone;
}

SceneOptions SceneOptionsFrom(const SceneFlags& f) {
  SceneOptions options;
  options.lod.pixel_threshold = f.full ? 1e-9 : f.error;
  options.lod.point_budget = f.full ? 0 : f.budget;
  if (!(f.cluster_error >= 0) || !std::isfinite(f.cluster_error)) {
    throw Error::InvalidArgument("--cluster-error must be finite and >= 0");
  }
  // Every particle: the cut with the threshold 0 (or the leaves, node by node).
  options.cluster_error = f.full && f.cluster_error > 0 ? 1e-300 : f.cluster_error;
  options.color = ParseColorMode(f.color);
  options.splat_path = ParseSplatPath(f.splat);
  if (!(f.compute_radius >= 0) || !std::isfinite(f.compute_radius)) {
    throw Error::InvalidArgument("--compute-radius must be finite and >= 0 pixels");
  }
  options.compute_radius = f.compute_radius;
  options.cpu_cache_bytes = static_cast<std::size_t>(ParseByteSize(f.cache, "--cache"));
  return options;
}

void CheckMaxRadius(const SceneFlags& f, double gl_max_blob_radius) {
  if (f.max_radius > gl_max_blob_radius) {
    throw Error::InvalidArgument("--max-radius " + std::to_string(f.max_radius) + ": this OpenGL draws blobs up to " +
                                 std::to_string(gl_max_blob_radius) + " pixels");
  }
}

std::vector<std::uint64_t> SelectedIds(const SceneFlags& f, const Dataset& dataset, std::uint32_t epoch) {
  std::vector<std::uint64_t> ids;
  if (!f.select.empty()) ids = ReadIdFile(f.select);
  if (!f.select_box.empty()) {
    const std::vector<double> v = ParseNumberList(f.select_box, "--select-box");
    if (v.size() != 6) throw Error::InvalidArgument("--select-box: expected 6 numbers x0,y0,z0,x1,y1,z1");
    const std::vector<std::uint64_t> in_box = ParticleIdsInBox(dataset, epoch, {v[0], v[1], v[2]}, {v[3], v[4], v[5]});
    ids.insert(ids.end(), in_box.begin(), in_box.end());
  }
  return ids;
}

}  // namespace octocosm
