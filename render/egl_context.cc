// The EGL backend of CreateHeadlessContext: a GPU driver without a display.
// Picks the first EGL device (EGL_EXT_platform_device), so it works on compute
// servers with no X server; falls back to the default display.
#include <EGL/egl.h>
#include <EGL/eglext.h>

#include <cstdio>
#include <string>
#include <vector>

#include "base/error.h"
#include "render/gl_context.h"

namespace octocosm {
namespace {

std::string EglErrorText() {
  char code[16];
  std::snprintf(code, sizeof code, "0x%04X", static_cast<unsigned>(eglGetError()));
  return std::string("EGL error ") + code;
}

EGLDisplay OpenDisplay() {
  auto query_devices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
  auto platform_display =
      reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (query_devices != nullptr && platform_display != nullptr) {
    EGLint count = 0;
    if (query_devices(0, nullptr, &count) && count > 0) {
      std::vector<EGLDeviceEXT> devices(static_cast<std::size_t>(count));
      if (query_devices(count, devices.data(), &count)) {
        for (EGLint i = 0; i < count; ++i) {
          EGLDisplay display = platform_display(EGL_PLATFORM_DEVICE_EXT, devices[static_cast<std::size_t>(i)], nullptr);
          EGLint major = 0, minor = 0;
          if (display != EGL_NO_DISPLAY && eglInitialize(display, &major, &minor)) return display;
        }
      }
    }
  }
  EGLDisplay display = eglGetDisplay(EGL_DEFAULT_DISPLAY);
  EGLint major = 0, minor = 0;
  if (display == EGL_NO_DISPLAY || !eglInitialize(display, &major, &minor)) {
    throw Error::NotSupported("EGL", "no EGL display could be initialised (" + EglErrorText() + ")");
  }
  return display;
}

class EglContext final : public GlContext {
 public:
  EglContext() {
    display_ = OpenDisplay();
    if (!eglBindAPI(EGL_OPENGL_API)) throw Error::NotSupported("EGL", "the driver has no desktop OpenGL (" + EglErrorText() + ")");
    const EGLint config_attributes[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
    EGLConfig config = nullptr;
    EGLint configs = 0;
    if (!eglChooseConfig(display_, config_attributes, &config, 1, &configs) || configs == 0) {
      throw Error::NotSupported("EGL", "no OpenGL-capable EGL configuration (" + EglErrorText() + ")");
    }
    const EGLint context_attributes[] = {EGL_CONTEXT_MAJOR_VERSION, 4, EGL_CONTEXT_MINOR_VERSION, 5,
                                         EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                         EGL_NONE};
    context_ = eglCreateContext(display_, config, EGL_NO_CONTEXT, context_attributes);
    if (context_ == EGL_NO_CONTEXT) {
      throw Error::NotSupported("EGL", "could not create an OpenGL 4.5 core context (" + EglErrorText() + ")");
    }
    // The renderer draws into framebuffer objects; a 1x1 pbuffer serves
    // drivers without EGL_KHR_surfaceless_context.
    const char* extensions = eglQueryString(display_, EGL_EXTENSIONS);
    if (extensions == nullptr || std::string(extensions).find("EGL_KHR_surfaceless_context") == std::string::npos) {
      const EGLint pbuffer_attributes[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
      surface_ = eglCreatePbufferSurface(display_, config, pbuffer_attributes);
    }
    MakeCurrent();
    LoadGlFunctions(reinterpret_cast<GlProcLoader>(eglGetProcAddress), "EGL");
  }
  ~EglContext() override {
    eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    if (surface_ != EGL_NO_SURFACE) eglDestroySurface(display_, surface_);
    eglDestroyContext(display_, context_);
    eglTerminate(display_);
  }

  void MakeCurrent() override {
    if (!eglMakeCurrent(display_, surface_, surface_, context_)) {
      throw Error::NotSupported("EGL", "could not make the context current (" + EglErrorText() + ")");
    }
  }

 private:
  EGLDisplay display_ = EGL_NO_DISPLAY;
  EGLContext context_ = EGL_NO_CONTEXT;
  EGLSurface surface_ = EGL_NO_SURFACE;
};

}  // namespace

std::unique_ptr<GlContext> CreateEglContext() { return std::make_unique<EglContext>(); }

}  // namespace octocosm
