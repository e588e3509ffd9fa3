// octocosm render: pictures of a store, headless (OSMesa, or EGL on a GPU).
// One PNG for a camera, numbered PNGs for a camera path, or the reference
// picture of all particles from the original snapshot.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "index/particle_lookup.h"
#include "render/offscreen_renderer.h"
#include "render/render_view.h"
#include "storage/error.h"
#include "tools/camera_flags.h"
#include "tools/camera_path.h"
#include "tools/cli_util.h"
#include "tools/cmd_query.h"
#include "tools/commands.h"
#include "tools/image_io.h"
#include "tools/read_flags.h"
#include "tools/reference_render.h"

namespace octocosm {
namespace {

struct RenderFlags {
  std::string store, output = "octocosm.png", hdr, path, frames, reference, backend = "osmesa";
  int width = 1280, height = 720;
  double time = 0;
  double error = 1;
  std::uint64_t budget = 0;
  bool full = false;
  CameraFlags camera;
  std::string color = "density", colormap = "magma", attribute_colormap, color_range, curve = "log";
  double exposure = 0, percentile = 99.5, decades = 4, softening = 1e-3, max_radius = kDefaultMaxBlobRadius;
  std::string select, select_box, cache = "1G";
  ReadFlags read;
  unsigned threads = 0;
  bool quiet = false;
};

ToneMapSettings ToneFrom(const RenderFlags& f) {
  ToneMapSettings tone;
  tone.curve = ParseToneCurve(f.curve);
  tone.exposure = f.exposure;
  tone.auto_percentile = f.percentile;
  tone.log_decades = f.decades;
  tone.asinh_softening = f.softening;
  tone.density_map = ParseColorMap(f.colormap);
  tone.color = ParseColorMode(f.color);
  tone.attribute_map = !f.attribute_colormap.empty() ? ParseColorMap(f.attribute_colormap)
                       : tone.color == ColorMode::kLineOfSightVelocity ? ColorMapId::kCoolwarm
                                                                        : ColorMapId::kViridis;
  if (!f.color_range.empty()) {
    const std::vector<double> v = ParseNumberList(f.color_range, "--color-range");
    if (v.size() != 2 || !(v[0] < v[1])) throw Error::InvalidArgument("--color-range: expected two numbers low,high with low < high");
    tone.attribute_low = v[0];
    tone.attribute_high = v[1];
  }
  tone.Validate();
  return tone;
}

std::vector<std::uint64_t> SelectedIds(const RenderFlags& f, const Dataset& dataset, std::uint32_t epoch) {
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

void PrintSummary(const RenderFlags& f, const std::string& what, const Picture& p) {
  if (f.quiet) return;
  std::fprintf(stderr,
               "render: %s %dx%d: %llu points in %llu nodes%s, %.3f s; exposure %.4g%s\n", what.c_str(), p.rgb.width,
               p.rgb.height, static_cast<unsigned long long>(p.stats.points_drawn),
               static_cast<unsigned long long>(p.stats.nodes_selected),
               p.stats.budget_reached ? " (point budget reached)" : "", p.seconds, p.tone.exposure,
               f.exposure > 0 ? "" : " (automatic)");
}

void RunRender(const RenderFlags& f) {
  const Dataset dataset = Dataset::Open(f.store);
  if (!(f.time >= 0 && f.time <= dataset.epoch_count() - 1.0)) {
    throw Error::InvalidArgument("--time " + std::to_string(f.time) + " is outside the store's epochs 0.." +
                                 std::to_string(dataset.epoch_count() - 1));
  }
  if (!(f.error > 0)) throw Error::InvalidArgument("--error must be > 0 pixels");
  const ToneMapSettings tone = ToneFrom(f);
  const auto epoch_at = [&](double time) { return static_cast<std::uint32_t>(std::lround(time)); };
  const double aspect = static_cast<double>(f.width) / f.height;
  const Cube& cube = dataset.cube(epoch_at(f.time));

  if (!f.reference.empty()) {
    // The ground truth: every particle of the snapshot, on the CPU.
    if (!f.path.empty()) throw Error::InvalidArgument("--reference renders one picture; it does not take --path");
    if (f.time != std::floor(f.time)) throw Error::InvalidArgument("--reference renders an epoch: give a whole --time");
    const RenderView view(CameraFromFlags(f.camera, cube, aspect, OverviewPosition(cube, f.camera.fov)), f.width, f.height,
                          f.max_radius);
    const std::vector<std::uint64_t> ids = SelectedIds(f, dataset, epoch_at(f.time));
    const SelectionSet selection(ids);
    ReferenceRenderOptions options;
    options.read = ReadOptionsFrom(f.read);
    options.color = tone.color;
    options.selection = ids.empty() ? nullptr : &selection;
    options.threads = f.threads;
    ReferenceRenderStats stats;
    const HdrImage hdr = RenderReference(dataset, epoch_at(f.time), f.reference, view, options, &stats);
    const ToneMapParameters parameters = ResolveToneMap(tone, MeasureImage(hdr, tone.color));
    WritePng(f.output, ToBytes(ToneMap(hdr, parameters)));
    if (!f.hdr.empty()) WritePfm(f.hdr, hdr);
    if (!f.quiet) {
      std::fprintf(stderr, "render: reference %s %dx%d: %llu particles, %llu drawn, %.3f s; exposure %.4g%s\n",
                   f.output.c_str(), f.width, f.height, static_cast<unsigned long long>(stats.particles),
                   static_cast<unsigned long long>(stats.points_drawn), stats.seconds, parameters.exposure,
                   f.exposure > 0 ? "" : " (automatic)");
    }
    return;
  }

  SceneOptions options;
  options.lod.pixel_threshold = f.full ? 1e-9 : f.error;
  options.lod.point_budget = f.full ? 0 : f.budget;
  options.color = tone.color;
  options.cpu_cache_bytes = static_cast<std::size_t>(ParseByteSize(f.cache, "--cache"));
  OffscreenRenderer renderer(dataset, ParseHeadlessBackend(f.backend), options);
  if (f.max_radius > renderer.max_blob_radius()) {
    throw Error::InvalidArgument("--max-radius " + std::to_string(f.max_radius) + ": this OpenGL draws blobs up to " +
                                 std::to_string(renderer.max_blob_radius()) + " pixels");
  }
  const std::vector<std::uint64_t> ids = SelectedIds(f, dataset, epoch_at(f.time));
  renderer.scene().SetSelection(ids);

  if (f.path.empty()) {
    const RenderView view(CameraFromFlags(f.camera, cube, aspect, OverviewPosition(cube, f.camera.fov)), f.width, f.height,
                          f.max_radius);
    const Picture picture = renderer.Render(view, f.time, tone, !f.hdr.empty());
    WritePng(f.output, picture.rgb);
    if (!f.hdr.empty()) WritePfm(f.hdr, *picture.hdr);
    PrintSummary(f, f.output, picture);
    return;
  }

  // A movie: one PNG per frame of the camera path, the exposure smoothed.
  if (f.frames.empty()) throw Error::InvalidArgument("--path needs --frames DIR for the numbered pictures");
  const CameraPath path = CameraPath::Load(f.path, cube);
  std::filesystem::create_directories(f.frames);
  ExposureSmoother smoother;
  for (std::size_t k = 0; k < path.frame_count(); ++k) {
    const CameraPathFrame frame = path.Frame(k);
    const double time = std::clamp(frame.epoch, 0.0, dataset.epoch_count() - 1.0);
    const Cube& frame_cube = dataset.cube(epoch_at(time));
    CameraFlags camera = f.camera;
    Camera c = frame.camera;
    c.aspect = aspect;
    c.near = f.camera.near > 0 ? f.camera.near : frame_cube.size * 1e-6;
    double d2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double d = c.position[a] - (frame_cube.origin[a] + frame_cube.size / 2);
      d2 += d * d;
    }
    c.far = f.camera.far > 0 ? f.camera.far : std::sqrt(d2) + frame_cube.size;
    const RenderView view(c, f.width, f.height, f.max_radius);
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05zu.png", k);
    const std::string file = (std::filesystem::path(f.frames) / name).string();
    const Picture picture = renderer.Render(view, time, tone, false, &smoother, 1 / path.fps());
    WritePng(file, picture.rgb);
    PrintSummary(f, file, picture);
  }
}

}  // namespace

void AddRenderCommand(CLI::App& app) {
  auto flags = std::make_shared<RenderFlags>();
  RenderFlags& f = *flags;
  CLI::App* cmd = app.add_subcommand(
      "render",
      "Render a store to PNG without a window (OpenGL 4.5 through OSMesa, or EGL on a GPU). Each frame draws the\n"
      "level of detail its camera needs: nodes in view, refined until their points are --error pixels apart,\n"
      "within --budget points. Points are blobs of a cubic kernel sized by their smoothing lengths, added up in\n"
      "a float buffer (mass per pixel) and tone mapped. --time between two epochs interpolates the particles'\n"
      "motion. --reference draws every particle of the original snapshot on the CPU instead: the ground truth.\n"
      "See docs/RENDERING.md.");
  cmd->add_option("store", f.store, "store directory")->required();
  cmd->add_option("-o,--output", f.output, "PNG to write")->default_val("octocosm.png");
  cmd->add_option("--width", f.width, "image width, pixels")->default_val(1280)->check(CLI::Range(1, 16384));
  cmd->add_option("--height", f.height, "image height, pixels")->default_val(720)->check(CLI::Range(1, 16384));
  AddCameraFlags(*cmd, f.camera);
  cmd->add_option("--time", f.time, "epoch to show; a fraction interpolates between two epochs (e.g. 2.25)")->default_val(0);
  cmd->add_option("--error", f.error, "level of detail: refine while points are more than this many pixels apart")->default_val(1);
  cmd->add_option("--budget", f.budget, "most points to draw (0: no limit)")->default_val(0);
  cmd->add_flag("--full", f.full, "draw every particle (every leaf in view), ignoring --error and --budget");
  cmd->add_option("--color", f.color, "colour: density, speed, los-velocity, dispersion (line-of-sight velocity dispersion) or type")
      ->default_val("density");
  cmd->add_option("--colormap", f.colormap, "colour map of density: magma, inferno, viridis, coolwarm, gray")->default_val("magma");
  cmd->add_option("--attribute-colormap", f.attribute_colormap, "colour map of the attribute (default: viridis; coolwarm for los-velocity)");
  cmd->add_option("--color-range", f.color_range, "attribute values at the ends of its colour map, low,high (default: 1st-99th percentile)");
  cmd->add_option("--curve", f.curve, "tone curve: log or asinh")->default_val("log");
  cmd->add_option("--exposure", f.exposure, "mass per pixel shown at full brightness (0: automatic)")->default_val(0);
  cmd->add_option("--percentile", f.percentile, "automatic exposure: this percentile of the lit pixels' mass")->default_val(99.5);
  cmd->add_option("--decades", f.decades, "log curve: decades of density below the exposure that stay visible")->default_val(4);
  cmd->add_option("--softening", f.softening, "asinh curve: linear below exposure * softening")->default_val(1e-3);
  cmd->add_option("--max-radius", f.max_radius, "largest blob radius, pixels")->default_val(kDefaultMaxBlobRadius);
  cmd->add_option("--select", f.select, "highlight the particle IDs listed in this file (one per line)");
  cmd->add_option("--select-box", f.select_box, "highlight the particles in the box x0,y0,z0,x1,y1,z1 (at --time's nearest epoch)");
  cmd->add_option("--hdr", f.hdr, "also write the mass per pixel as a PFM image");
  cmd->add_option("--path", f.path, "camera path (JSON, docs/RENDERING.md): render every frame of it");
  cmd->add_option("--frames", f.frames, "directory for the numbered frames of --path");
  cmd->add_option("--reference", f.reference, "render every particle of this snapshot (the one --time's epoch was ingested from) on the CPU");
  AddReadFlags(*cmd, f.read);
  cmd->add_option("--threads", f.threads, "threads of the reference renderer (default: all cores)")->default_val(0);
  cmd->add_option("--cache", f.cache, "memory for blocks read from the store")->default_val("1G");
  cmd->add_option("--backend", f.backend, "headless OpenGL: osmesa (software, always there) or egl (a GPU driver)")
      ->default_val("osmesa");
  cmd->add_flag("-q,--quiet", f.quiet, "no summary on stderr");
  cmd->callback([flags] { RunRender(*flags); });
}

}  // namespace octocosm
