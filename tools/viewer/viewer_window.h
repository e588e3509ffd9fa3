// The viewer's window: GLFW, an OpenGL 4.5 core context with the renderer's
// GL functions loaded (render/gl_context.h), and Dear ImGui on top (its GLFW
// and OpenGL 3 backends from Debian's libimgui-dev). Set up in the
// constructor and torn down in reverse order in the destructor, like Dear
// ImGui's example_glfw_opengl3.
//
// A frame: BeginFrame() (events, a new ImGui frame), drawing into the back
// buffer (framebuffer 0), ImGui widgets, EndFrame() (ImGui drawn over the
// picture, buffers swapped).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "render/image.h"

struct GLFWwindow;

namespace octocosm {

// A key going down, or repeating while held (GLFW key codes).
struct KeyPress {
  int glfw_key = 0;
  bool repeat = false;
};

class ViewerWindow {
 public:
  // Opens a window of width x height screen coordinates. Throws
  // Error::NotSupported naming what failed: no display to open it on, or no
  // OpenGL 4.5 core context.
  ViewerWindow(int width, int height, const std::string& title, bool vsync);
  ~ViewerWindow();
  ViewerWindow(const ViewerWindow&) = delete;
  ViewerWindow& operator=(const ViewerWindow&) = delete;

  bool ShouldClose() const;
  void BeginFrame();
  void EndFrame();

  // The framebuffer in pixels (0 x 0 while minimized).
  int framebuffer_width() const { return framebuffer_width_; }
  int framebuffer_height() const { return framebuffer_height_; }
  // Binds the window's framebuffer for drawing with a viewport covering it,
  // cleared to black.
  void BindAndClear();
  // The back buffer as drawn so far in this frame.
  RgbImage ReadBackBuffer() const;
  // Frames per second, averaged over the last 120 frames (Dear ImGui's count).
  double frames_per_second() const;
  // The context's renderer and version (render/gl_context.h CurrentGlDescription).
  const std::string& description() const { return description_; }
  // Every key press among this frame's events, in order. Dear ImGui 1.86
  // keeps only whether a key is down at the frame, so a key pressed and
  // released between two frames (a quick tap while llvmpipe draws a few
  // frames a second) would never be seen; these are not lost.
  const std::vector<KeyPress>& keys_pressed() const { return keys_pressed_; }

 private:
  // Each part tears down what it set up, so a constructor that fails half
  // way leaves nothing behind.
  struct GlfwLibrary {
    GlfwLibrary();
    ~GlfwLibrary();
  };
  struct WindowDeleter {
    void operator()(GLFWwindow* window) const;
  };
  struct ImGuiSession {
    explicit ImGuiSession(GLFWwindow* window);
    ~ImGuiSession();
  };
  static void RecordKeyPress(GLFWwindow* window, int key, int scancode, int action, int mods);

  GlfwLibrary glfw_;
  std::unique_ptr<GLFWwindow, WindowDeleter> window_;
  std::unique_ptr<ImGuiSession> imgui_;
  int framebuffer_width_ = 0, framebuffer_height_ = 0;
  std::string description_;
  std::vector<KeyPress> keys_pressed_;
};

}  // namespace octocosm
