#include "render/gl_objects.h"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "base/error.h"

namespace octocosm {

void DeleteGlBuffer(GLuint name) { glDeleteBuffers(1, &name); }
void DeleteGlTexture(GLuint name) { glDeleteTextures(1, &name); }
void DeleteGlFramebuffer(GLuint name) { glDeleteFramebuffers(1, &name); }
void DeleteGlVertexArray(GLuint name) { glDeleteVertexArrays(1, &name); }
void DeleteGlProgram(GLuint name) { glDeleteProgram(name); }

GlBuffer MakeGlBuffer(std::size_t bytes, const void* data, GLbitfield flags) {
  GLuint name = 0;
  glCreateBuffers(1, &name);
  GlBuffer buffer(name);
  // Zero-sized storage is an error in GL; an empty block still gets a buffer.
  glNamedBufferStorage(name, static_cast<GLsizeiptr>(bytes > 0 ? bytes : 4), bytes > 0 ? data : nullptr, flags);
  CheckGlError("allocating a GPU buffer of " + std::to_string(bytes) + " bytes");
  return buffer;
}

namespace {

const char* StageName(GLenum type) {
  switch (type) {
    case GL_VERTEX_SHADER: return "vertex";
    case GL_FRAGMENT_SHADER: return "fragment";
    case GL_COMPUTE_SHADER: return "compute";
    default: return "shader";
  }
}

std::string ShaderLog(GLuint shader) {
  GLint length = 0;
  glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
  std::string log(static_cast<std::size_t>(std::max(length, 1)), '\0');
  glGetShaderInfoLog(shader, length, nullptr, log.data());
  return log.c_str();
}

std::string ProgramLog(GLuint program) {
  GLint length = 0;
  glGetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
  std::string log(static_cast<std::size_t>(std::max(length, 1)), '\0');
  glGetProgramInfoLog(program, length, nullptr, log.data());
  return log.c_str();
}

}  // namespace

GlProgram BuildGlProgram(const std::string& name, std::initializer_list<ShaderStage> stages) {
  GlProgram program(glCreateProgram());
  std::vector<GLuint> shaders;
  auto cleanup = [&] {
    for (GLuint s : shaders) glDeleteShader(s);
  };
  for (const ShaderStage& stage : stages) {
    const GLuint shader = glCreateShader(stage.type);
    shaders.push_back(shader);
    std::vector<const char*> sources{"#version 450 core\n"};
    sources.insert(sources.end(), stage.sources.begin(), stage.sources.end());
    glShaderSource(shader, static_cast<GLsizei>(sources.size()), sources.data(), nullptr);
    glCompileShader(shader);
    GLint ok = GL_FALSE;
    glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
    if (!ok) {
      const std::string log = ShaderLog(shader);
      cleanup();
      throw Error::NotSupported("OpenGL", "the " + std::string(StageName(stage.type)) + " shader of '" + name +
                                              "' does not compile: " + log);
    }
    glAttachShader(program.get(), shader);
  }
  glLinkProgram(program.get());
  GLint ok = GL_FALSE;
  glGetProgramiv(program.get(), GL_LINK_STATUS, &ok);
  cleanup();
  if (!ok) throw Error::NotSupported("OpenGL", "the program '" + name + "' does not link: " + ProgramLog(program.get()));
  return program;
}

bool GlHasExtension(const char* name) {
  GLint count = 0;
  glGetIntegerv(GL_NUM_EXTENSIONS, &count);
  for (GLint i = 0; i < count; ++i) {
    const auto* extension = reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, static_cast<GLuint>(i)));
    if (extension != nullptr && std::strcmp(extension, name) == 0) return true;
  }
  return false;
}

void CheckGlError(const std::string& what) {
  const GLenum error = glGetError();
  if (error == GL_NO_ERROR) return;
  while (glGetError() != GL_NO_ERROR) {
  }
  char code[16];
  std::snprintf(code, sizeof code, "0x%04X", error);
  throw Error::NotSupported("OpenGL", what + " failed with GL error " + code +
                                          (error == GL_OUT_OF_MEMORY ? " (out of GPU memory)" : ""));
}

}  // namespace octocosm
