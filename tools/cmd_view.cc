// octocosm view: a store in a window (GLFW, OpenGL 4.5 core) with a Dear
// ImGui overlay. RunView reads top to bottom like Dear ImGui's
// example_glfw_opengl3: set-up, the frame loop, and shutdown in reverse
// order (by scope). The parts live in tools/viewer/, one job per file.
//
// A frame never waits for the disk: SceneRenderer::Stream draws what is on
// the GPU (parents stand in for children still on their way) and asks the
// prefetcher for the rest, most important first; while playing, the next
// epoch's blocks stream ahead of the playhead. Box selections are worked out
// on a background thread. Every epoch's tree is loaded before the first frame.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "render/render_view.h"
#include "render/scene_renderer.h"
#include "render/splat_renderer.h"
#include "render/tone_map.h"
#include "tools/camera_flags.h"
#include "tools/camera_path.h"
#include "tools/commands.h"
#include "tools/image_io.h"
#include "tools/render_flags.h"
#include "tools/viewer/camera_controller.h"
#include "tools/viewer/overlay.h"
#include "tools/viewer/playback.h"
#include "tools/viewer/screen_region.h"
#include "tools/viewer/screenshot_request.h"
#include "tools/viewer/selection_job.h"
#include "tools/viewer/viewer_input.h"
#include "tools/viewer/viewer_script.h"
#include "tools/viewer/viewer_window.h"
#include "tools/store_flags.h"

namespace octocosm {
namespace {

struct ViewFlags {
  std::string store, path, screenshot;
  int width = 1280, height = 720;
  SceneFlags scene;
  bool no_vsync = false;
  double fps_cap = 0;
  bool hide_overlay = false;
  bool exit_after_path = false;
  double settle_timeout = 60;
  bool play = false, no_loop = false;
  double speed = 0.5;
  bool quiet = false;
};

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// A name for the P key's screenshot that is not taken yet in the current directory.
std::string FreeScreenshotName() {
  for (int n = 1;; ++n) {
    char name[40];
    std::snprintf(name, sizeof name, "octocosm-view-%03d.png", n);
    if (!std::filesystem::exists(name)) return name;
  }
}

// The frame's summary for stderr, after a screenshot's name.
std::string DescribeFrame(int width, int height, const FrameStats& stats, double time, double exposure) {
  char text[200];
  std::snprintf(text, sizeof text, "%dx%d: %llu points, epoch %.3g, exposure %.4g", width, height,
                static_cast<unsigned long long>(stats.points_drawn), time, exposure);
  return text;
}

ViewerScriptOptions ScriptOptionsFrom(const ViewFlags& f, const Cube& start_cube, const Dataset& dataset) {
  ViewerScriptOptions options;
  options.store = f.store;
  if (!f.path.empty()) options.path = CameraPath::Load(f.path, start_cube, dataset);
  options.screenshot = f.screenshot;
  options.exit_after = f.exit_after_path;
  options.settle_timeout = f.settle_timeout;
  return options;
}

// Step 5 of a frame: exposure (smoothed over `seconds` when automatic, so
// that blocks arriving or bright clumps entering the view do not make it
// flicker), and tone mapping into the window.
ToneMapParameters ToneMapIntoWindow(const ToneMapSettings& tone, double seconds, SplatRenderer& splat, ViewerWindow& window,
                                    ExposureSmoother& smoother) {
  // The statistics come a frame or two late, so that the CPU never waits
  // for the GPU to finish drawing; only the first frame waits for its own.
  const ImageStatistics image = splat.MeasureLate();
  if (tone.exposure == 0 && image.max_density > 0) smoother.Update(AutomaticExposure(tone, image), seconds);
  const ToneMapParameters parameters = ResolveToneMap(tone, image, tone.exposure > 0 ? 0.0 : smoother.current());
  window.BindAndClear();
  splat.ToneMapToViewport(parameters, 0, 0);
  return parameters;
}

// What the user and the script have set, carried from frame to frame.
struct ViewerState {
  ViewerState(const Camera& start_camera, double cube_size, std::uint32_t epochs, double start_time)
      : controller(start_camera, cube_size), playback(epochs, start_time) {}
  CameraController controller;
  Playback playback;
  OverlayRequests overlay_requests;  // from the previous frame's overlay
  SelectionJob selection_job;
  std::string selection_message;
  std::string status;
  ScreenshotRequest screenshot_request;  // the P key's, or the overlay's button's
  ExposureSmoother smoother;
};

// Step 1 of a frame: what the user asked for, by key, mouse or the overlay's
// buttons. The camera and the clock are the script's while it runs.
void ApplyUserCommands(const ViewerCommands& commands, int height, bool script_running, double elapsed, double now,
                       const Camera& start_camera, ViewerSettings& settings, SceneRenderer& scene, ViewerState& state) {
  if (!script_running) {
    CameraController& controller = state.controller;
    if (commands.toggle_camera_mode) {
      controller.set_mode(controller.mode() == CameraMode::kOrbit ? CameraMode::kFly : CameraMode::kOrbit);
    }
    if (commands.reset_view) controller.JumpTo(start_camera);
    if (height > 0) controller.Update(commands.camera, height);
    if (commands.toggle_playing) state.playback.Toggle();
    if (commands.step_epochs != 0) state.playback.Step(commands.step_epochs);
    state.playback.Advance(elapsed);
  }
  if (commands.toggle_overlay) settings.show_overlay = !settings.show_overlay;
  if (commands.clear_selection || state.overlay_requests.clear_selection) {
    state.selection_job.Cancel();
    scene.SetSelection({});
    state.selection_message = "cleared";
  }
  if (commands.cancel && state.selection_job.running()) {
    state.selection_job.Cancel();
    state.selection_message = "abandoned";
  }
  if (state.overlay_requests.id_file) {
    state.selection_job.Start(IdFileSelectionWork(*state.overlay_requests.id_file));
    state.selection_message = "reading " + *state.overlay_requests.id_file;
  }
  if (commands.screenshot || state.overlay_requests.screenshot) state.screenshot_request.Ask(now);
}

// Step 3: a box drawn starts a selection in the background; a finished one
// goes to the GPU.
void UpdateSelection(const ViewerCommands& commands, const Dataset& dataset, double time, const RenderView& view,
                     bool quiet, SceneRenderer& scene, ViewerState& state) {
  if (commands.box_drawn) {
    if ((dataset.columns() & ColumnBit(ColumnId::kId)) == 0) {
      state.selection_message = "this store holds no particle IDs: nothing can be selected";
    } else {
      state.selection_job.Start(BoxSelectionWork(dataset, NearestEpoch(time), RectangleFrustum(view, *commands.box_drawn)));
      state.selection_message = "selecting the particles in the box...";
    }
  }
  if (std::optional<SelectionResult> result = state.selection_job.TakeResult()) {
    state.selection_message = result->message;
    if (!quiet) std::fprintf(stderr, "view: selection: %s (%.2f s)\n", result->message.c_str(), result->seconds);
    if (!result->failed) {
      try {
        scene.SetSelection(result->ids);
      } catch (const Error& e) {
        state.selection_message = e.what();
      }
    }
  }
}

// Step 6, the P key's screenshot (the script's is taken by the caller): of
// the picture without the overlay, once the view is complete or the request
// has waited long enough.
void TakeRequestedScreenshot(ViewerWindow& window, const FrameStats& stats, const std::string& frame_text, double now,
                             bool quiet, ViewerState& state) {
  const ScreenshotRequest::Take take = state.screenshot_request.FrameDrawn(stats.blocks_missing, now);
  if (take == ScreenshotRequest::Take::kNotYet) {
    if (state.screenshot_request.waiting()) {
      state.status = "screenshot: waiting for " + std::to_string(stats.blocks_missing) + " blocks to load";
    }
    return;
  }
  // A screenshot that cannot be written is a message, not the end of the session.
  try {
    const std::string name = FreeScreenshotName();
    WritePng(name, window.ReadBackBuffer());
    const std::string completeness = take == ScreenshotRequest::Take::kComplete
                                         ? "view complete"
                                         : std::to_string(stats.blocks_missing) + " blocks still loading";
    state.status = "screenshot " + name + " (" + completeness + ")";
    if (!quiet) std::fprintf(stderr, "view: %s %s, %s\n", name.c_str(), frame_text.c_str(), completeness.c_str());
  } catch (const Error& e) {
    state.status = e.what();
  }
}

// Step 7: what the overlay shows.
OverlayReport MakeOverlayReport(const ViewerWindow& window, const FrameStats& stats, SplatRenderer& splat, const SceneRenderer& scene,
                                const Dataset& dataset, const Camera& camera, double exposure, bool script_running,
                                const ViewerState& state) {
  OverlayReport report;
  report.fps = window.frames_per_second();
  report.frame_ms = report.fps > 0 ? 1000 / report.fps : 0;
  report.frame = stats;
  report.gpu_times = splat.LatestGpuTimes(false);
  report.splat_path = SplatPathName(splat.frame_path());
  report.cache = scene.cache_stats();
  report.disk = scene.disk_reads();
  report.exposure = exposure;
  report.last_error = scene.last_error();
  report.selected = scene.selection_size();
  report.selection_message = state.selection_message;
  report.selection_running = state.selection_job.running();
  report.store_has_ids = (dataset.columns() & ColumnBit(ColumnId::kId)) != 0;
  report.store_has_velocity = (dataset.columns() & ColumnBit(ColumnId::kVelocity)) != 0;
  report.store_links_clusters = (dataset.cluster_columns() & kClusterLinkColumns) == kClusterLinkColumns;
  report.camera_mode = state.controller.mode();
  report.camera_position = camera.position;
  report.fly_speed = state.controller.fly_speed();
  report.script_running = script_running;
  report.status = state.status;
  report.gl_description = window.description();
  return report;
}

void RunView(ViewFlags f) {  // a copy: the time flags resolve into it
  // The store and everything the flags decide, before a window opens: a bad
  // flag or store fails fast, with or without a display.
  const Dataset dataset = Dataset::Open(f.store);
  ResolveSceneFlags(f.scene, dataset);
  if (f.fps_cap < 0) throw Error::InvalidArgument("--fps-cap must be >= 0 (0: no cap)");
  if (!(f.settle_timeout > 0)) throw Error::InvalidArgument("--settle-timeout must be > 0 seconds");
  const SceneOptions scene_options = SceneOptionsFrom(f.scene);
  ViewerSettings settings{ToneSettingsFrom(f.scene), scene_options.lod, !f.hide_overlay, scene_options.cluster_error};
  const Cube& start_cube = dataset.cube(NearestEpoch(f.scene.time));
  const Camera start_camera = CameraFromFlags(f.scene.camera, start_cube, static_cast<double>(f.width) / f.height,
                                              OverviewPosition(start_cube, f.scene.camera.fov));
  const std::vector<std::uint64_t> initial_selection = SelectedIds(f.scene, dataset, NearestEpoch(f.scene.time));
  const ViewerScriptOptions script_options = ScriptOptionsFrom(f, start_cube, dataset);
  ViewerScript script(script_options);

  // The window with its OpenGL 4.5 core context and Dear ImGui.
  ViewerWindow window(f.width, f.height, "octocosm view " + f.store, !f.no_vsync);

  // The renderer, on the window's context (declared after the window, so its
  // GL objects go first).
  SplatRenderer splat;
  CheckMaxRadius(f.scene, splat.max_blob_radius());
  SceneRenderer scene(dataset, splat, scene_options);
  scene.SetSelection(initial_selection);
  if (!f.quiet) {
    std::fprintf(stderr, "view: %s; %u epochs; %zu IDs highlighted\n", window.description().c_str(),
                 dataset.epoch_count(), scene.selection_size());
  }

  // The user's side of things.
  ViewerState state(start_camera, start_cube.size, dataset.epoch_count(), f.scene.time);
  state.playback.set_speed(f.speed);
  state.playback.set_loop(!f.no_loop);
  state.playback.set_playing(f.play);
  state.selection_message = initial_selection.empty() ? "" : "from --select / --select-box";
  ViewerInput input;
  Overlay overlay;
  const double path_frame_seconds = script_options.path ? 1 / script_options.path->fps() : 0;

  const auto started = Clock::now();
  auto last_frame = started;
  bool quit = false;
  while (!quit && !window.ShouldClose()) {
    const auto frame_start = Clock::now();
    const double elapsed = std::chrono::duration<double>(frame_start - last_frame).count();
    last_frame = frame_start;
    window.BeginFrame();
    const int width = window.framebuffer_width(), height = window.framebuffer_height();

    // 1. What the user asked for.
    const ViewerCommands commands = input.Read(height, window.keys_pressed());
    ApplyUserCommands(commands, height, script.running(), elapsed, SecondsSince(started), start_camera, settings, scene, state);
    if (width == 0 || height == 0) {  // minimised: nothing to draw, and no hurry
      window.EndFrame();
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      continue;
    }

    // 2. This frame's camera and time: the script's path, else the user's.
    const std::optional<CameraPathFrame> path_frame = script.PathFrame();
    Camera camera = path_frame ? path_frame->camera : state.controller.camera(1);
    camera.aspect = static_cast<double>(width) / height;
    const double time = path_frame ? std::clamp(path_frame->epoch, 0.0, state.playback.last()) : state.playback.time();
    ApplyDepthRange(f.scene.camera, dataset.cube(NearestEpoch(time)), camera);
    const RenderView view(camera, width, height, f.scene.max_radius);

    // 3. Selections.
    UpdateSelection(commands, dataset, time, view, f.quiet, scene, state);

    // 4. The scene, streamed. The script's last view is drawn complete once
    // a block has failed to stream: Complete() waits for every block and
    // throws the failed read's Error, or draws the whole view if it now reads.
    scene.SetLod(settings.lod);
    scene.SetClusterError(settings.cluster_error);
    scene.SetColorMode(settings.tone.color);
    const FrameStats stats = script.settling() && !scene.last_error().empty()
                                 ? scene.Complete(view, time)
                                 : scene.Stream(view, time, state.playback.playing() && !script.running());

    // 5. Exposure and tone mapping.
    const ToneMapParameters tone =
        ToneMapIntoWindow(settings.tone, script.running() ? path_frame_seconds : elapsed, splat, window, state.smoother);

    // 6. Screenshots, of the picture without the overlay.
    const std::string frame_text = DescribeFrame(width, height, stats, time, tone.exposure);
    const bool script_was_running = script.running();
    const ViewerScript::AfterFrame after = script.FrameDrawn(stats.blocks_missing, SecondsSince(started));
    if (after.take_screenshot) {
      WritePng(f.screenshot, window.ReadBackBuffer());
      if (!f.quiet) {
        std::fprintf(stderr, "view: %s %s, after %.2f s\n", f.screenshot.c_str(), frame_text.c_str(), SecondsSince(started));
      }
    }
    TakeRequestedScreenshot(window, stats, frame_text, SecondsSince(started), f.quiet, state);
    if (script_was_running && !script.running()) {
      // The user takes over where the script left the camera and the clock.
      state.controller.JumpTo(camera);
      state.playback.set_time(time);
    }
    quit = after.quit;

    // 7. The overlay, and the frame goes to the screen.
    if (commands.box_drawing) Overlay::DrawSelectionBox(*commands.box_drawing, height);
    state.overlay_requests = {};
    if (settings.show_overlay) {
      state.overlay_requests = overlay.Draw(
          MakeOverlayReport(window, stats, splat, scene, dataset, camera, tone.exposure, script.running(), state), settings,
          state.playback);
    }
    window.EndFrame();

    if (f.fps_cap > 0) {
      std::this_thread::sleep_until(frame_start + std::chrono::duration_cast<Clock::duration>(
                                                      std::chrono::duration<double>(1 / f.fps_cap)));
    }
  }
}

}  // namespace

void AddViewCommand(CLI::App& app) {
  auto flags = std::make_shared<ViewFlags>();
  ViewFlags& f = *flags;
  CLI::App* cmd = app.add_subcommand(
      "view",
      "Explore a store in a window (OpenGL 4.5 core through GLFW) with an overlay of statistics and controls.\n"
      "Orbit or fly through the data, play through the epochs, select particles with a box. Frames never wait\n"
      "for the disk: what has not arrived is drawn coarser until it does. The camera, time, level-of-detail,\n"
      "colour and selection flags are those of 'octocosm render'. For scripts and tests: --path plays a camera\n"
      "path, --screenshot writes its last view once every block of it is loaded, --exit-after-path quits then.\n"
      "Controls: docs/VIEWER.md, or the overlay's 'controls' section.");
  AddStoreArgument(*cmd, f.store);
  cmd->add_option("--width", f.width, "window width")->default_val(1280)->check(CLI::Range(64, 16384));
  cmd->add_option("--height", f.height, "window height")->default_val(720)->check(CLI::Range(64, 16384));
  AddSceneFlags(*cmd, f.scene);
  cmd->add_flag("--play", f.play, "start playing through the epochs");
  cmd->add_option("--speed", f.speed, "playback speed, epochs per second")->default_val(0.5)->check(CLI::PositiveNumber);
  cmd->add_flag("--no-loop", f.no_loop, "stop at the last epoch instead of starting again from the first");
  cmd->add_flag("--no-vsync", f.no_vsync, "draw frames as fast as they come instead of with the display's refresh");
  cmd->add_option("--fps-cap", f.fps_cap, "most frames per second (0: no cap)")->default_val(0);
  cmd->add_flag("--hide-overlay", f.hide_overlay, "start with the overlay hidden (H shows it)");
  cmd->add_option("--path", f.path, "camera path (JSON, docs/RENDERING.md) to play, one path frame per frame drawn");
  cmd->add_option("--screenshot", f.screenshot,
                  "PNG of the last view of --path (or of the starting view), once every block of it is loaded");
  cmd->add_flag("--exit-after-path", f.exit_after_path, "quit after --path has played (and --screenshot is written)");
  cmd->add_option("--settle-timeout", f.settle_timeout, "seconds the script's last view may take to load")
      ->default_val(60);
  cmd->add_flag("-q,--quiet", f.quiet, "nothing on stderr but errors (no context, selections or screenshots)");
  cmd->callback([flags] { RunView(*flags); });
}

}  // namespace octocosm
