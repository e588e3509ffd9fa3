// The OSMesa backend of CreateHeadlessContext: Mesa's software rasterizer.
#include <GL/osmesa.h>

#include <array>

#include "render/gl_context.h"
#include "storage/error.h"

namespace octocosm {
namespace {

class OsMesaContext final : public GlContext {
 public:
  OsMesaContext() {
    const int attributes[] = {OSMESA_FORMAT,         OSMESA_RGBA,          OSMESA_DEPTH_BITS,          0,
                              OSMESA_STENCIL_BITS,   0,                    OSMESA_ACCUM_BITS,          0,
                              OSMESA_PROFILE,        OSMESA_CORE_PROFILE,  OSMESA_CONTEXT_MAJOR_VERSION, 4,
                              OSMESA_CONTEXT_MINOR_VERSION, 5,             0};
    context_ = OSMesaCreateContextAttribs(attributes, nullptr);
    if (context_ == nullptr) {
      throw Error::NotSupported("OSMesa", "could not create an OpenGL 4.5 core context (is libosmesa6 >= 20 installed?)");
    }
    MakeCurrent();
    LoadGlFunctions(reinterpret_cast<GlProcLoader>(OSMesaGetProcAddress), "OSMesa");
  }
  ~OsMesaContext() override { OSMesaDestroyContext(context_); }

  void MakeCurrent() override {
    // The renderer draws into framebuffer objects; OSMesa still wants a
    // buffer for the default framebuffer, so it gets a one-pixel one.
    if (!OSMesaMakeCurrent(context_, pixel_.data(), GL_UNSIGNED_BYTE, 1, 1)) {
      throw Error::NotSupported("OSMesa", "could not make the context current");
    }
  }

 private:
  OSMesaContext context_ = nullptr;
  std::array<unsigned char, 4> pixel_{};
};

}  // namespace

std::unique_ptr<GlContext> CreateOsMesaContext() { return std::make_unique<OsMesaContext>(); }

#ifndef OCTOCOSM_HAVE_EGL
std::unique_ptr<GlContext> CreateEglContext() {
  throw Error::NotSupported("EGL", "this build has no EGL support (install libegl-dev and rebuild)");
}
#endif

}  // namespace octocosm
