// The OSMesa backend of CreateHeadlessContext: Mesa's software rasterizer.
// libOSMesa is loaded when first asked for, not linked: it brings LLVM with
// it, and a machine that renders through EGL on a GPU need not have it.
#include <GL/osmesa.h>
#include <dlfcn.h>

#include <array>
#include <string>

#include "render/gl_context.h"
#include "storage/error.h"

namespace octocosm {
namespace {

struct OsMesaLibrary {
  decltype(&OSMesaCreateContextAttribs) create = nullptr;
  decltype(&OSMesaMakeCurrent) make_current = nullptr;
  decltype(&OSMesaDestroyContext) destroy = nullptr;
  decltype(&OSMesaGetProcAddress) get_proc_address = nullptr;
};

const OsMesaLibrary& LoadOsMesa() {
  static const OsMesaLibrary library = [] {
    void* handle = dlopen("libOSMesa.so.8", RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) handle = dlopen("libOSMesa.so", RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      const char* why = dlerror();
      throw Error::NotSupported("OSMesa", std::string("libOSMesa could not be loaded (install libosmesa6, or use "
                                                      "--backend egl on a GPU): ") + (why ? why : "not found"));
    }
    OsMesaLibrary l;
    l.create = reinterpret_cast<decltype(l.create)>(dlsym(handle, "OSMesaCreateContextAttribs"));
    l.make_current = reinterpret_cast<decltype(l.make_current)>(dlsym(handle, "OSMesaMakeCurrent"));
    l.destroy = reinterpret_cast<decltype(l.destroy)>(dlsym(handle, "OSMesaDestroyContext"));
    l.get_proc_address = reinterpret_cast<decltype(l.get_proc_address)>(dlsym(handle, "OSMesaGetProcAddress"));
    if (!l.create || !l.make_current || !l.destroy || !l.get_proc_address) {
      throw Error::NotSupported("OSMesa", "libOSMesa lacks OSMesaCreateContextAttribs (Mesa 11 or later is needed)");
    }
    return l;  // never unloaded: contexts may outlive any one caller
  }();
  return library;
}

class OsMesaContext final : public GlContext {
 public:
  OsMesaContext() : library_(LoadOsMesa()) {
    const int attributes[] = {OSMESA_FORMAT,         OSMESA_RGBA,          OSMESA_DEPTH_BITS,          0,
                              OSMESA_STENCIL_BITS,   0,                    OSMESA_ACCUM_BITS,          0,
                              OSMESA_PROFILE,        OSMESA_CORE_PROFILE,  OSMESA_CONTEXT_MAJOR_VERSION, 4,
                              OSMESA_CONTEXT_MINOR_VERSION, 5,             0};
    context_ = library_.create(attributes, nullptr);
    if (context_ == nullptr) {
      throw Error::NotSupported("OSMesa", "could not create an OpenGL 4.5 core context (is libosmesa6 >= 20 installed?)");
    }
    MakeCurrent();
    // Through a local function: a GlProcLoader is a plain function pointer.
    static const OsMesaLibrary* loader = &library_;
    LoadGlFunctions([](const char* name) { return reinterpret_cast<void (*)()>(loader->get_proc_address(name)); },
                    "OSMesa");
  }
  ~OsMesaContext() override { library_.destroy(context_); }

  void MakeCurrent() override {
    // The renderer draws into framebuffer objects; OSMesa still wants a
    // buffer for the default framebuffer, so it gets a one-pixel one.
    if (!library_.make_current(context_, pixel_.data(), GL_UNSIGNED_BYTE, 1, 1)) {
      throw Error::NotSupported("OSMesa", "could not make the context current");
    }
  }

 private:
  const OsMesaLibrary& library_;
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
