#include "render/gl_context.h"

#include <glad/gl.h>

#include "base/error.h"

namespace octocosm {

std::unique_ptr<GlContext> CreateOsMesaContext();
std::unique_ptr<GlContext> CreateEglContext();

HeadlessBackend ParseHeadlessBackend(const std::string& name) {
  if (name == "osmesa") return HeadlessBackend::kOsMesa;
  if (name == "egl") return HeadlessBackend::kEgl;
  throw Error::InvalidArgument("unknown headless GL backend '" + name + "': expected osmesa or egl");
}

std::unique_ptr<GlContext> CreateHeadlessContext(HeadlessBackend backend) {
  switch (backend) {
    case HeadlessBackend::kOsMesa: return CreateOsMesaContext();
    case HeadlessBackend::kEgl: return CreateEglContext();
  }
  throw Error::InvalidArgument("unknown headless GL backend");
}

void LoadGlFunctions(GlProcLoader get_proc_address, const std::string& context_name) {
  const int version = gladLoadGL(reinterpret_cast<GLADloadfunc>(get_proc_address));
  if (version == 0) throw Error::NotSupported(context_name, "could not load the OpenGL functions");
  if (GLAD_VERSION_MAJOR(version) * 10 + GLAD_VERSION_MINOR(version) < 45) {
    throw Error::NotSupported(context_name, "OpenGL 4.5 core is required, the context offers " +
                                                std::to_string(GLAD_VERSION_MAJOR(version)) + "." +
                                                std::to_string(GLAD_VERSION_MINOR(version)) + " (" +
                                                CurrentGlDescription() + ")");
  }
}

std::string CurrentGlDescription() {
  const auto* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  const auto* version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
  return std::string(renderer ? renderer : "unknown renderer") + ", OpenGL " + (version ? version : "unknown version");
}

}  // namespace octocosm
