// Scripted runs of the viewer, for tests and movies (`octocosm view --path
// camera.json --screenshot out.png --exit-after-path`): the camera path is
// played one path frame per drawn frame (not in real time, so a slow machine
// shows every frame); then frames continue at the path's last camera until
// the view is complete, i.e. every block it selects is on the GPU
// (FrameStats::blocks_missing == 0), so that the screenshot is the whole
// picture and not whatever had arrived. Without a path the script is just
// that wait at the starting camera. After it the user has the camera, or
// the viewer quits.
//
// No window, no GL: the frame loop asks which camera to draw and reports
// each frame drawn.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "tools/camera_path.h"

namespace octocosm {

struct ViewerScriptOptions {
  std::string store;  // names the store in errors
  std::optional<CameraPath> path;
  std::string screenshot;       // PNG of the complete last view; empty: none
  bool exit_after = false;      // quit after it
  double settle_timeout = 60;   // seconds the last view may take to load
};

class ViewerScript {
 public:
  explicit ViewerScript(ViewerScriptOptions options);

  // Whether the script drives the camera (until the last view is complete).
  bool running() const { return state_ != State::kDone; }
  // Whether the script waits at its last view.
  bool settling() const { return state_ == State::kSettling; }
  // The path's frame to draw now (its last one while settling); nullopt
  // without a path or once the script is done.
  std::optional<CameraPathFrame> PathFrame() const;

  struct AfterFrame {
    bool take_screenshot = false;  // write options.screenshot from this frame
    bool quit = false;
  };
  // Reports a frame drawn at `seconds` (any steady clock) with `blocks_missing`
  // blocks of its view not on the GPU. Throws Error::Io when the last view is
  // still incomplete settle_timeout seconds after the script reached it.
  AfterFrame FrameDrawn(std::uint64_t blocks_missing, double seconds);

  const ViewerScriptOptions& options() const { return options_; }

 private:
  enum class State { kPlayingPath, kSettling, kDone };

  ViewerScriptOptions options_;
  State state_;
  std::size_t frame_ = 0;
  std::optional<double> settle_start_;
};

}  // namespace octocosm
