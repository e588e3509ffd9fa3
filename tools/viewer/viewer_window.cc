#include "tools/viewer/viewer_window.h"

#include <dlfcn.h>
#include <link.h>

#include <glad/gl.h>
// After glad: GLFW must not pull in a GL header of its own.
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>

#include "base/error.h"
#include "render/gl_context.h"

namespace octocosm {
namespace {

// GLFW reports failures through a callback; the last one is kept to say what
// went wrong when a call then returns failure.
std::string last_glfw_error = "no details";

void RecordGlfwError(int code, const char* description) {
  last_glfw_error = std::string(description ? description : "?") + " (GLFW error " + std::to_string(code) + ")";
}

#if defined(__SANITIZE_ADDRESS__)
// AddressSanitizer builds only. At teardown GLFW unloads libGL, and Mesa its
// GL driver (when the display closes); the allocations they never free then
// point into unmapped code, which LeakSanitizer reports as leaks in
// "<unknown module>" that no suppression (tests/lsan.supp) can name. Every
// shared object loaded once the window is open stays loaded until the
// process ends, so those allocations stay theirs (and reachable).
void KeepLoadedLibrariesLoaded() {
  dl_iterate_phdr(
      [](dl_phdr_info* info, std::size_t, void*) {
        if (info->dlpi_name != nullptr && info->dlpi_name[0] != '\0') {
          dlopen(info->dlpi_name, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);  // nullptr for the vDSO: nothing to keep
        }
        return 0;
      },
      nullptr);
}
#endif

}  // namespace

ViewerWindow::GlfwLibrary::GlfwLibrary() {
  glfwSetErrorCallback(RecordGlfwError);
  if (!glfwInit()) {
    throw Error::NotSupported("GLFW", "cannot open a window: " + last_glfw_error +
                                          ". The viewer needs a display: run it in an X11 session, or under "
                                          "xvfb-run for a virtual one");
  }
}

ViewerWindow::GlfwLibrary::~GlfwLibrary() { glfwTerminate(); }

void ViewerWindow::WindowDeleter::operator()(GLFWwindow* window) const { glfwDestroyWindow(window); }

ViewerWindow::ImGuiSession::ImGuiSession(GLFWwindow* window) {
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini left in the user's directory
  ImGui::StyleColorsDark();
  ImGui_ImplGlfw_InitForOpenGL(window, true);
  // Its OpenGL 3 backend loads its own few GL functions (not through glad).
  if (!ImGui_ImplOpenGL3_Init("#version 450 core")) {
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
    throw Error::NotSupported("Dear ImGui", "its OpenGL 3 backend could not load the OpenGL functions it needs");
  }
}

ViewerWindow::ImGuiSession::~ImGuiSession() {
  ImGui_ImplOpenGL3_Shutdown();
  ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
}

ViewerWindow::ViewerWindow(int width, int height, const std::string& title, bool vsync) {
  // The renderer needs OpenGL 4.5 core (render/gl_context.h).
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 5);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  // No depth or stencil buffer: splats add up, nothing is depth tested.
  glfwWindowHint(GLFW_DEPTH_BITS, 0);
  glfwWindowHint(GLFW_STENCIL_BITS, 0);
  window_.reset(glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr));
  if (!window_) {
    throw Error::NotSupported("GLFW", "cannot create a window with an OpenGL 4.5 core context: " + last_glfw_error);
  }
  glfwMakeContextCurrent(window_.get());
  glfwSwapInterval(vsync ? 1 : 0);
  LoadGlFunctions(glfwGetProcAddress, std::string("GLFW window (") + glfwGetVersionString() + ")");
  description_ = CurrentGlDescription();
  // Before Dear ImGui's callbacks, which call the ones they replace.
  glfwSetWindowUserPointer(window_.get(), this);
  glfwSetKeyCallback(window_.get(), RecordKeyPress);
  imgui_ = std::make_unique<ImGuiSession>(window_.get());
  glfwGetFramebufferSize(window_.get(), &framebuffer_width_, &framebuffer_height_);
#if defined(__SANITIZE_ADDRESS__)
  KeepLoadedLibrariesLoaded();
#endif
}

void ViewerWindow::RecordKeyPress(GLFWwindow* window, int key, int, int action, int) {
  if (action == GLFW_RELEASE) return;
  static_cast<ViewerWindow*>(glfwGetWindowUserPointer(window))->keys_pressed_.push_back({key, action == GLFW_REPEAT});
}

ViewerWindow::~ViewerWindow() {
  imgui_.reset();  // while its context is current
}

bool ViewerWindow::ShouldClose() const { return glfwWindowShouldClose(window_.get()); }

double ViewerWindow::frames_per_second() const { return ImGui::GetIO().Framerate; }

void ViewerWindow::BeginFrame() {
  keys_pressed_.clear();
  glfwPollEvents();
  glfwGetFramebufferSize(window_.get(), &framebuffer_width_, &framebuffer_height_);
  ImGui_ImplOpenGL3_NewFrame();
  ImGui_ImplGlfw_NewFrame();
  ImGui::NewFrame();
}

void ViewerWindow::BindAndClear() {
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glViewport(0, 0, framebuffer_width_, framebuffer_height_);
  glClearColor(0, 0, 0, 1);
  glClear(GL_COLOR_BUFFER_BIT);
}

RgbImage ViewerWindow::ReadBackBuffer() const {
  RgbImage image;
  image.width = framebuffer_width_;
  image.height = framebuffer_height_;
  image.rgb.resize(3 * static_cast<std::size_t>(image.width) * image.height);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  glReadBuffer(GL_BACK);
  GLint alignment = 4;
  glGetIntegerv(GL_PACK_ALIGNMENT, &alignment);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);  // rows of 3 * width bytes, unpadded
  glReadPixels(0, 0, image.width, image.height, GL_RGB, GL_UNSIGNED_BYTE, image.rgb.data());
  glPixelStorei(GL_PACK_ALIGNMENT, alignment);
  return image;
}

void ViewerWindow::EndFrame() {
  ImGui::Render();
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glViewport(0, 0, framebuffer_width_, framebuffer_height_);
  ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
  glfwSwapBuffers(window_.get());
}

}  // namespace octocosm
