// OpenGL 4.5 core contexts for the renderer.
//
// The renderer (render/splat_renderer.h) draws into its own framebuffer
// objects, so it needs only a context that is current on the calling thread:
//
//  - headless, through OSMesa (Mesa's llvmpipe on the CPU; works on any
//    machine, which is what tests and CI use), or through EGL (a real GPU's
//    driver without a display, e.g. NVIDIA's on a compute server);
//  - in a window: the GLFW viewer creates its own context and calls
//    LoadGlFunctions with glfwGetProcAddress.
//
// Every context loads the same glad-generated entry points, so one renderer
// runs on all of them. A context belongs to the thread that created it.
#pragma once

#include <memory>
#include <string>

namespace octocosm {

enum class HeadlessBackend {
  kOsMesa,  // software rasterizer, always available
  kEgl,     // the system's EGL driver (a GPU), where one is installed
};

// "osmesa" / "egl" -> HeadlessBackend. Throws Error::InvalidArgument for
// anything else.
HeadlessBackend ParseHeadlessBackend(const std::string& name);

class GlContext {
 public:
  virtual ~GlContext() = default;
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  // Makes the context current on the calling thread.
  virtual void MakeCurrent() = 0;

 protected:
  GlContext() = default;
};

// Creates a headless OpenGL 4.5 core context, makes it current on this thread
// and loads the GL functions. Throws Error::NotSupported naming the backend
// and what failed (no driver, no 4.5 core profile, ...).
std::unique_ptr<GlContext> CreateHeadlessContext(HeadlessBackend backend);

// Loads the GL entry points for the context current on this thread through
// `get_proc_address` and checks that it is OpenGL 4.5 or later. Throws
// Error::NotSupported otherwise.
using GlProcLoader = void (*(*)(const char* name))();
void LoadGlFunctions(GlProcLoader get_proc_address, const std::string& context_name);

// "Mesa llvmpipe (LLVM 15.0.6, 256 bits), OpenGL 4.5 (Core Profile) Mesa 22.3.6":
// the renderer and version strings of the current context.
std::string CurrentGlDescription();

}  // namespace octocosm
