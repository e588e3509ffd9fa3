// Owning handles for OpenGL objects, and shader programs built from the
// embedded sources with errors that say which shader failed and why. All
// functions need a current OpenGL 4.5 context (render/gl_context.h); objects
// must be destroyed while it is still current.
#pragma once

#include <glad/gl.h>

#include <initializer_list>
#include <string>
#include <utility>
#include <vector>

namespace octocosm {

// A GL name with its deleter: move-only, deleted on destruction.
template <void (*Delete)(GLuint)>
class GlName {
 public:
  GlName() = default;
  explicit GlName(GLuint name) : name_(name) {}
  GlName(GlName&& other) noexcept : name_(std::exchange(other.name_, 0)) {}
  GlName& operator=(GlName&& other) noexcept {
    if (this != &other) {
      Reset();
      name_ = std::exchange(other.name_, 0);
    }
    return *this;
  }
  GlName(const GlName&) = delete;
  GlName& operator=(const GlName&) = delete;
  ~GlName() { Reset(); }

  GLuint get() const { return name_; }
  explicit operator bool() const { return name_ != 0; }
  void Reset() {
    if (name_ != 0) Delete(name_);
    name_ = 0;
  }

 private:
  GLuint name_ = 0;
};

void DeleteGlBuffer(GLuint name);
void DeleteGlTexture(GLuint name);
void DeleteGlFramebuffer(GLuint name);
void DeleteGlVertexArray(GLuint name);
void DeleteGlProgram(GLuint name);

using GlBuffer = GlName<DeleteGlBuffer>;
using GlTexture = GlName<DeleteGlTexture>;
using GlFramebuffer = GlName<DeleteGlFramebuffer>;
using GlVertexArray = GlName<DeleteGlVertexArray>;
using GlProgram = GlName<DeleteGlProgram>;

// An immutable-storage buffer of `bytes` bytes (glNamedBufferStorage),
// initialised from `data` when not null.
GlBuffer MakeGlBuffer(std::size_t bytes, const void* data, GLbitfield flags);

// A shader stage: its sources (from render_shaders.h, shared files first),
// compiled as one text after "#version 450 core".
struct ShaderStage {
  GLenum type;  // GL_VERTEX_SHADER, GL_FRAGMENT_SHADER, GL_COMPUTE_SHADER
  std::vector<const char*> sources;
};

// Compiles and links a program. Throws Error::NotSupported("OpenGL", ...)
// naming `name`, the stage and the driver's log: a shader that does not build
// on a 4.5 core driver is a bug or an unusable driver, not a user error.
GlProgram BuildGlProgram(const std::string& name, std::initializer_list<ShaderStage> stages);

// Whether the current context offers the extension `name` (e.g.
// "GL_NV_shader_atomic_float").
bool GlHasExtension(const char* name);

// Throws Error::NotSupported naming `what` when glGetError reports an error
// (GL_OUT_OF_MEMORY most likely: textures or buffers too large for the device).
void CheckGlError(const std::string& what);

}  // namespace octocosm
