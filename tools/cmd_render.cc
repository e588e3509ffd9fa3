// octocosm render: pictures of a store, headless (OSMesa, or EGL on a GPU).
// One PNG for a camera, numbered PNGs for a camera path, or the reference
// picture of all particles from the original snapshot.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "render/offscreen_renderer.h"
#include "render/render_view.h"
#include "base/error.h"
#include "tools/camera_flags.h"
#include "tools/camera_path.h"
#include "tools/commands.h"
#include "tools/cli_util.h"
#include "tools/image_io.h"
#include "ingest/ingest.h"
#include "tools/read_flags.h"
#include "tools/reference_render.h"
#include "tools/render_flags.h"
#include "tools/store_flags.h"

namespace octocosm {
namespace {

struct RenderFlags {
  std::string store, output = "octocosm.png", hdr, path, frames, reference, backend = "osmesa";
  int width = 1280, height = 720;
  SceneFlags scene;
  ReadFlags read;
  unsigned threads = 0;
  int neighbours = kDefaultNeighbours;
  std::string memory, temp_dir;
  bool quiet = false;
};

void PrintSummary(const RenderFlags& f, const std::string& what, const Picture& p) {
  if (f.quiet) return;
  std::fprintf(stderr,
               "render: %s %dx%d: %llu points in %llu nodes%s, %.3f s; exposure %.4g%s%s\n", what.c_str(), p.rgb.width,
               p.rgb.height, static_cast<unsigned long long>(p.stats.points_drawn),
               static_cast<unsigned long long>(p.stats.nodes_selected),
               p.stats.budget_reached ? " (point budget reached)" : "", p.seconds, p.tone.exposure,
               f.scene.exposure > 0 ? "" : " (automatic)",
               p.stats.highlight_exact
                   ? ("; " + std::to_string(p.stats.points_highlighted) + " selected particles highlighted at full detail").c_str()
                   : "");
}

void RunRender(RenderFlags f) {  // a copy: the time flags resolve into it
  const Dataset dataset = Dataset::Open(f.store);
  ResolveSceneFlags(f.scene, dataset);
  const ToneMapSettings tone = ToneSettingsFrom(f.scene);
  const double aspect = static_cast<double>(f.width) / f.height;
  const Cube& cube = dataset.cube(NearestEpoch(f.scene.time));

  if (!f.reference.empty()) {
    // The ground truth: every particle of the snapshot, on the CPU.
    if (!f.path.empty()) throw Error::InvalidArgument("--reference renders one picture; it does not take --path");
    if (f.scene.time != std::floor(f.scene.time)) {
      throw Error::InvalidArgument("--reference renders an epoch: give a whole --time");
    }
    const RenderView view(CameraFromFlags(f.scene.camera, cube, aspect, OverviewPosition(cube, f.scene.camera.fov)),
                          f.width, f.height, f.scene.max_radius);
    const std::vector<std::uint64_t> ids = SelectedIds(f.scene, dataset, NearestEpoch(f.scene.time));
    const SelectionSet selection(ids);
    ReferenceRenderOptions options;
    options.read = ReadOptionsFrom(f.read);
    options.color = tone.color;
    options.selection = ids.empty() ? nullptr : &selection;
    options.threads = f.threads;
    options.smoothing.neighbours = f.neighbours;
    options.smoothing.memory_budget = f.memory.empty() ? DefaultMemoryBudget() : ParseByteSize(f.memory, "--memory");
    options.smoothing.temp_dir = f.temp_dir;
    options.smoothing.quiet = f.quiet;
    ReferenceRenderStats stats;
    const HdrImage hdr = RenderReference(f.reference, view, options, &stats);
    const ToneMapParameters parameters = ResolveToneMap(tone, MeasureImage(hdr, tone.color));
    WritePng(f.output, ToBytes(ToneMap(hdr, parameters)));
    if (!f.hdr.empty()) WritePfm(f.hdr, hdr);
    if (!f.quiet) {
      std::fprintf(stderr,
                   "render: reference %s %dx%d: %llu particles, %llu drawn, %.3f s (smoothing lengths %.3f s: %llu "
                   "from the snapshot, %llu from %d neighbours); exposure %.4g%s\n",
                   f.output.c_str(), f.width, f.height, static_cast<unsigned long long>(stats.particles),
                   static_cast<unsigned long long>(stats.points_drawn), stats.seconds, stats.smoothing.seconds,
                   static_cast<unsigned long long>(stats.smoothing.given),
                   static_cast<unsigned long long>(stats.smoothing.searched), f.neighbours, parameters.exposure,
                   f.scene.exposure > 0 ? "" : " (automatic)");
    }
    return;
  }

  OffscreenRenderer renderer(dataset, ParseHeadlessBackend(f.backend), SceneOptionsFrom(f.scene));
  CheckMaxRadius(f.scene, renderer.max_blob_radius());
  const std::vector<std::uint64_t> ids = SelectedIds(f.scene, dataset, NearestEpoch(f.scene.time));
  renderer.scene().SetSelection(ids);

  if (f.path.empty()) {
    const RenderView view(CameraFromFlags(f.scene.camera, cube, aspect, OverviewPosition(cube, f.scene.camera.fov)),
                          f.width, f.height, f.scene.max_radius);
    const Picture picture = renderer.Render(view, f.scene.time, tone, !f.hdr.empty());
    WritePng(f.output, picture.rgb);
    if (!f.hdr.empty()) WritePfm(f.hdr, *picture.hdr);
    PrintSummary(f, f.output, picture);
    return;
  }

  // A movie: one PNG per frame of the camera path, the exposure smoothed.
  if (f.frames.empty()) throw Error::InvalidArgument("--path needs --frames DIR for the numbered pictures");
  const CameraPath path = CameraPath::Load(f.path, cube, dataset);
  std::filesystem::create_directories(f.frames);
  ExposureSmoother smoother;
  for (std::size_t k = 0; k < path.frame_count(); ++k) {
    const CameraPathFrame frame = path.Frame(k);
    const double time = std::clamp(frame.epoch, 0.0, dataset.epoch_count() - 1.0);
    const Cube& frame_cube = dataset.cube(NearestEpoch(time));
    Camera c = frame.camera;
    c.aspect = aspect;
    ApplyDepthRange(f.scene.camera, frame_cube, c);
    const RenderView view(c, f.width, f.height, f.scene.max_radius);
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
      "motion; --redshift or --scale-factor give the time as a cosmological store records it. --reference\n"
      "draws every particle of the original snapshot on the CPU instead: the ground truth. See docs/RENDERING.md.");
  AddStoreArgument(*cmd, f.store);
  cmd->add_option("-o,--output", f.output, "PNG to write")->default_val("octocosm.png");
  cmd->add_option("--width", f.width, "image width, pixels")->default_val(1280)->check(CLI::Range(1, 16384));
  cmd->add_option("--height", f.height, "image height, pixels")->default_val(720)->check(CLI::Range(1, 16384));
  AddSceneFlags(*cmd, f.scene);
  cmd->add_option("--hdr", f.hdr, "also write the mass per pixel as a PFM image");
  cmd->add_option("--path", f.path, "camera path (JSON, docs/RENDERING.md): render every frame of it");
  cmd->add_option("--frames", f.frames, "directory for the numbered frames of --path");
  cmd->add_option("--reference", f.reference,
                  "render every particle of this snapshot on the CPU, each with the snapshot's own smoothing length or "
                  "the radius of its --neighbours nearest neighbours (the store gives only the camera)");
  cmd->add_option("--neighbours", f.neighbours, "--reference: neighbours a smoothing length encloses (as ingest's)")
      ->default_val(kDefaultNeighbours)
      ->check(CLI::Range(1, 4096));
  cmd->add_option("--memory", f.memory, "--reference: memory budget for the smoothing lengths, e.g. 2G (default: half the physical memory)");
  cmd->add_option("--temp-dir", f.temp_dir, "--reference: where temporary files go when the snapshot exceeds --memory (default: $TMPDIR or /tmp)");
  AddReadFlags(*cmd, f.read);
  cmd->add_option("--threads", f.threads, "--reference: threads (default: all cores)")->default_val(0);
  cmd->add_option("--backend", f.backend, "headless OpenGL: osmesa (software, always there) or egl (a GPU driver)")
      ->default_val("osmesa");
  cmd->add_flag("-q,--quiet", f.quiet, "no summary on stderr");
  cmd->callback([flags] { RunRender(*flags); });
}

}  // namespace octocosm
