// The viewer's overlay (Dear ImGui): what the renderer is doing (frame rate,
// points, nodes, blocks on their way and on the GPU, the block cache, bytes
// read, the exposure, the last error) and the controls that the mouse and
// keyboard do not cover (time, level of detail, colours and tone curve,
// selection). It only shows and edits values: the frame loop applies them.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "query/column_reader.h"
#include "query/lod_frontier.h"
#include "render/gpu_stage_timer.h"
#include "render/scene_renderer.h"
#include "render/tone_map.h"
#include "storage/block_cache.h"
#include "tools/viewer/camera_controller.h"
#include "tools/viewer/playback.h"
#include "tools/viewer/screen_region.h"

namespace octocosm {

// What the overlay edits.
struct ViewerSettings {
  ToneMapSettings tone;
  LodOptions lod;
  bool show_overlay = true;
  double cluster_error = 0;  // SceneOptions::cluster_error
};

// What it shows, from the frame just drawn.
struct OverlayReport {
  double fps = 0, frame_ms = 0;
  FrameStats frame;
  std::optional<GpuStageTimes> gpu_times;  // of a recent frame the GPU has finished
  const char* splat_path = "raster";       // how the frame's blobs were drawn (render/compute_splatter.h)
  CacheStats cache;
  ReadCounters disk;
  double exposure = 0;  // as tone mapped
  std::string last_error;
  std::size_t selected = 0;
  std::string selection_message;
  bool selection_running = false;
  bool store_has_ids = false;
  bool store_has_velocity = false;
  bool store_links_clusters = false;  // the level of detail can refine cluster by cluster
  CameraMode camera_mode = CameraMode::kOrbit;
  std::array<double, 3> camera_position{};
  double fly_speed = 0;
  bool script_running = false;
  std::string status;  // the latest notice (screenshot written, ...)
  std::string gl_description;
};

// What the user asked for with the overlay's buttons.
struct OverlayRequests {
  bool clear_selection = false;
  std::optional<std::string> id_file;  // select the IDs of this file
  bool screenshot = false;
};

class Overlay {
 public:
  OverlayRequests Draw(const OverlayReport& report, ViewerSettings& settings, Playback& playback);
  // The rectangle of a box selection being drawn (window coordinates of
  // render/render_view.h), shown whether or not the overlay is.
  static void DrawSelectionBox(const ScreenRectangle& box, int framebuffer_height);

 private:
  std::array<char, 1024> id_file_{};
};

}  // namespace octocosm
