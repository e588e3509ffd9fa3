#include "tools/viewer/viewer_input.h"

#include <algorithm>

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <imgui.h>

namespace octocosm {
namespace {

// How often `glfw_key` went down this frame; with `repeats`, also how often
// it repeated while held.
int Presses(const std::vector<KeyPress>& keys_pressed, int glfw_key, bool repeats) {
  return static_cast<int>(std::ranges::count_if(
      keys_pressed, [&](const KeyPress& k) { return k.glfw_key == glfw_key && (repeats || !k.repeat); }));
}
// The ImGui GLFW backend of Dear ImGui 1.86 indexes io.KeysDown by GLFW key codes.
bool Held(int glfw_key) { return ImGui::IsKeyDown(glfw_key); }
int Axis(int plus_key, int minus_key) { return (Held(plus_key) ? 1 : 0) - (Held(minus_key) ? 1 : 0); }

}  // namespace

ViewerCommands ViewerInput::Read(int framebuffer_height, const std::vector<KeyPress>& keys_pressed) {
  const ImGuiIO& io = ImGui::GetIO();
  const auto pressed = [&](int glfw_key) { return Presses(keys_pressed, glfw_key, false) > 0; };
  ViewerCommands c;
  c.camera.seconds = io.DeltaTime;
  const double sx = io.DisplayFramebufferScale.x, sy = io.DisplayFramebufferScale.y;
  const std::array<double, 2> mouse{io.MousePos.x * sx, io.MousePos.y * sy};
  const double dx = io.MouseDelta.x * sx, dy = io.MouseDelta.y * sy;

  bool escape_taken = false;
  // A box once started keeps the mouse until the button is released, even
  // over the overlay.
  if (box_start_ || !io.WantCaptureMouse) {
    if (!box_start_ && io.KeyShift && ImGui::IsMouseClicked(ImGuiMouseButton_Left)) box_start_ = mouse;
    if (box_start_) {
      // Window coordinates: y up from the bottom row.
      ScreenRectangle box{std::min((*box_start_)[0], mouse[0]), framebuffer_height - std::max((*box_start_)[1], mouse[1]),
                          std::max((*box_start_)[0], mouse[0]), framebuffer_height - std::min((*box_start_)[1], mouse[1])};
      const bool big_enough = box.width() >= kMinBoxPixels && box.height() >= kMinBoxPixels;
      if (!ImGui::IsMouseDown(ImGuiMouseButton_Left)) {
        if (big_enough) c.box_drawn = box;
        box_start_.reset();
      } else if (!io.WantCaptureKeyboard && pressed(GLFW_KEY_ESCAPE)) {
        box_start_.reset();
        escape_taken = true;
      } else {
        c.box_drawing = box;
      }
    } else {
      if (ImGui::IsMouseDown(ImGuiMouseButton_Left)) {
        c.camera.rotate_x = dx;
        c.camera.rotate_y = dy;
      }
      if (ImGui::IsMouseDown(ImGuiMouseButton_Right) || ImGui::IsMouseDown(ImGuiMouseButton_Middle)) {
        c.camera.pan_x = dx;
        c.camera.pan_y = dy;
      }
      c.camera.scroll = io.MouseWheel;
    }
  }

  if (!io.WantCaptureKeyboard) {
    c.camera.move = {Axis(GLFW_KEY_D, GLFW_KEY_A), Axis(GLFW_KEY_E, GLFW_KEY_Q), Axis(GLFW_KEY_W, GLFW_KEY_S)};
    c.camera.fast = io.KeyShift;
    c.toggle_camera_mode = pressed(GLFW_KEY_F);
    c.toggle_playing = pressed(GLFW_KEY_SPACE);
    // An arrow key held down steps on at the keyboard's repeat rate.
    c.step_epochs = Presses(keys_pressed, GLFW_KEY_RIGHT, true) - Presses(keys_pressed, GLFW_KEY_LEFT, true);
    c.reset_view = pressed(GLFW_KEY_R);
    c.clear_selection = pressed(GLFW_KEY_C);
    c.toggle_overlay = pressed(GLFW_KEY_H);
    c.screenshot = pressed(GLFW_KEY_P);
    c.cancel = pressed(GLFW_KEY_ESCAPE) && !escape_taken;
  }
  return c;
}

}  // namespace octocosm
