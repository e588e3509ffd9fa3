// What the user asks of the viewer in one frame, read from Dear ImGui's
// view of the mouse and keyboard (its GLFW backend feeds it), so that the
// overlay's widgets and the scene share one input path: whatever ImGui's own
// windows take (io.WantCaptureMouse / WantCaptureKeyboard) is left to them.
//
// Controls (docs/VIEWER.md lists them for users):
//   left drag              orbit about the pivot / look around (fly)
//   right or middle drag   pan
//   wheel                  orbit: move towards the pivot; fly: flying speed
//   W A S D, E Q           fly forward, left, back, right, up, down; shift: faster
//   shift + left drag      box select
//   F  orbit / fly     space  play / pause     left, right  previous / next epoch
//   R  reset the view  C  clear the selection  H  overlay on / off
//   P  screenshot      Esc  abandon a box being drawn or a selection being worked out
#pragma once

#include <optional>
#include <vector>

#include "tools/viewer/camera_controller.h"
#include "tools/viewer/screen_region.h"
#include "tools/viewer/viewer_window.h"

namespace octocosm {

struct ViewerCommands {
  CameraInput camera;
  bool toggle_camera_mode = false;
  bool toggle_playing = false;
  int step_epochs = 0;  // whole epochs forward (> 0) or back (< 0)
  bool reset_view = false;
  bool clear_selection = false;
  bool toggle_overlay = false;
  bool screenshot = false;
  bool cancel = false;
  std::optional<ScreenRectangle> box_drawn;     // shift + drag finished this frame
  std::optional<ScreenRectangle> box_drawing;   // shift + drag under way
};

class ViewerInput {
 public:
  // Rectangles smaller than this on a side are taken as clicks, not boxes.
  static constexpr double kMinBoxPixels = 3;

  // Reads the current ImGui frame's input (call after ImGui::NewFrame), and
  // the keys pressed among this frame's events (ViewerWindow::keys_pressed),
  // which decide the one-off commands (F, space, P, ...). Positions and drags
  // are in framebuffer pixels; rectangles in the window coordinates of
  // render/render_view.h (origin at the lower left).
  ViewerCommands Read(int framebuffer_height, const std::vector<KeyPress>& keys_pressed);

 private:
  std::optional<std::array<double, 2>> box_start_;  // framebuffer pixels, y down
};

}  // namespace octocosm
