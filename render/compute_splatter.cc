#include "render/compute_splatter.h"

#include <algorithm>
#include <string>
#include <vector>

#include "render/render_shaders.h"
#include "base/error.h"

namespace octocosm {
namespace {

// Storage-buffer bindings of shaders/splat_comp.glsl.
constexpr GLuint kAccumulationBinding = 17;
constexpr GLuint kLargeBlobsBinding = 18;
GLuint ColumnBinding(ColumnId id) {
  switch (id) {
    case ColumnId::kPosition: return 5;
    case ColumnId::kWeight: return 6;
    case ColumnId::kSmoothing: return 7;
    case ColumnId::kShape: return 8;
    case ColumnId::kVelocity: return 9;
    case ColumnId::kVelocityDispersion: return 10;
    case ColumnId::kType: return 11;
    case ColumnId::kId: return 12;
    case ColumnId::kDisplacement: return 13;
    case ColumnId::kPrevDisplacement: return 14;
    case ColumnId::kNextVelocity: return 15;
    case ColumnId::kPrevVelocity: return 16;
    case ColumnId::kRefineBound: return 19;  // the cluster cut's entries (render/cluster_links.h)
    case ColumnId::kChildCluster: return 0;  // never on the GPU (render/gpu_block.h)
  }
  return 0;
}

// The columns a program reads: always these four, and those `columns` asks for.
std::vector<ColumnId> ColumnsRead(const ComputeColumns& c) {
  std::vector<ColumnId> ids{ColumnId::kPosition, ColumnId::kWeight, ColumnId::kSmoothing, ColumnId::kShape};
  if (c.velocity) ids.push_back(ColumnId::kVelocity);
  if (c.dispersion) ids.push_back(ColumnId::kVelocityDispersion);
  if (c.type) ids.push_back(ColumnId::kType);
  if (c.id) ids.push_back(ColumnId::kId);
  if (c.links) ids.insert(ids.end(), {ColumnId::kDisplacement, ColumnId::kPrevDisplacement});
  if (c.hermite) ids.insert(ids.end(), {ColumnId::kNextVelocity, ColumnId::kPrevVelocity});
  if (c.cut) ids.push_back(ColumnId::kRefineBound);
  return ids;
}

// The storage buffers a program binds: the selection, the blocks' parameters,
// the draws, the accumulation and the large blobs, and its columns.
int StorageBuffersOf(const ComputeColumns& c) { return 5 + static_cast<int>(ColumnsRead(c).size()); }

unsigned KeyOf(const ComputeColumns& c) {
  return (c.velocity ? 1u : 0u) | (c.dispersion ? 2u : 0u) | (c.type ? 4u : 0u) | (c.id ? 8u : 0u) |
         (c.links ? 16u : 0u) | (c.hermite ? 32u : 0u) | (c.cut ? 64u : 0u);
}

constexpr std::size_t kLargeBlobBytes = 48;  // LargeBlob in shaders/splat_comp.glsl
constexpr std::size_t kLargeHeaderBytes = 16;
constexpr std::uint32_t kDefaultLargeCapacity = 1u << 20;
constexpr GLuint kMaxGroups = 65535;
constexpr GLuint kLargeBlobGroups = 2048;  // workgroups taking the large blobs in turn
constexpr const char* kAtomicFloat = "#extension GL_NV_shader_atomic_float : require\n";

GLint Location(const GlProgram& program, const char* name) { return glGetUniformLocation(program.get(), name); }

}  // namespace

bool ComputeSplatter::Supported() {
  GLint blocks = 0;
  glGetIntegerv(GL_MAX_COMPUTE_SHADER_STORAGE_BLOCKS, &blocks);
  return blocks >= 16 && GlHasExtension("GL_NV_shader_atomic_float");
}

ComputeSplatter::ComputeSplatter() {
  large_program_ = BuildGlProgram(
      "compute splat, large blobs",
      {{GL_COMPUTE_SHADER,
        {kAtomicFloat, shaders::kShaderSplatCommon, shaders::kShaderSplatAccumulate, shaders::kShaderSplatLargeComp}}});
  resolve_ = BuildGlProgram("accumulation resolve", {{GL_COMPUTE_SHADER, {shaders::kShaderAccumulationResolveComp}}});
  absent_column_ = MakeGlBuffer(16, nullptr, 0);
  glGetIntegerv(GL_MAX_COMPUTE_SHADER_STORAGE_BLOCKS, &max_storage_buffers_);
  GLint64 max_block = 0;
  glGetInteger64v(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &max_block);
  max_block_bytes_ = static_cast<std::uint64_t>(std::max<GLint64>(max_block, 1 << 24));
  GLint alignment = 16;
  glGetIntegerv(GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT, &alignment);
  // A base at a multiple of this many points starts every column (strides
  // of 1 to 8 bytes) at a multiple of the alignment.
  base_alignment_ = std::max<std::uint32_t>(256, static_cast<std::uint32_t>(std::max(alignment, 1)));
  // Eight bytes a point is the widest column (whole u64 IDs).
  const std::uint64_t span = std::min<std::uint64_t>(max_block_bytes_ / 8, 0x80000000u);
  max_span_points_ = static_cast<std::uint32_t>(span / base_alignment_ * base_alignment_);
  if (max_span_points_ < 2 * base_alignment_) {
    throw Error::NotSupported("OpenGL", "storage buffers of " + std::to_string(max_block_bytes_) +
                                            " bytes are too small for the compute path");
  }
  set_large_blob_capacity(kDefaultLargeCapacity);
  CheckGlError("setting up the compute path");
}

void ComputeSplatter::set_large_blob_capacity(std::uint32_t blobs) {
  large_capacity_ = std::max<std::uint32_t>(blobs, 1);
  const std::size_t bytes = kLargeHeaderBytes + std::size_t{large_capacity_} * kLargeBlobBytes;
  large_blobs_ = MakeGlBuffer(bytes, nullptr, GL_DYNAMIC_STORAGE_BIT);
  const std::uint32_t header[4] = {0, 0, 0, 0};  // count, padding
  glNamedBufferSubData(large_blobs_.get(), 0, sizeof header, header);
  CheckGlError("allocating the large blobs' list");
}

bool ComputeSplatter::Prepare(int width, int height) {
  const std::size_t bytes = std::size_t{16} * static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (bytes > max_block_bytes_) return false;
  if (bytes != accumulation_bytes_) {
    accumulation_ = MakeGlBuffer(bytes, nullptr, GL_DYNAMIC_STORAGE_BIT);
    const float zero = 0;
    glClearNamedBufferData(accumulation_.get(), GL_R32F, GL_RED, GL_FLOAT, &zero);
    accumulation_bytes_ = bytes;
    pending_ = false;
    CheckGlError("allocating the compute path's accumulation");
  }
  width_ = width;
  height_ = height;
  return true;
}

const GlProgram& ComputeSplatter::ProgramFor(const ComputeColumns& columns) {
  const unsigned key = KeyOf(columns);
  auto it = programs_.find(key);
  if (it != programs_.end()) return it->second;
  std::string defines = kAtomicFloat;
  if (columns.velocity) defines += "#define HAS_VELOCITY 1\n";
  if (columns.dispersion) defines += "#define HAS_DISPERSION 1\n";
  if (columns.type) defines += "#define HAS_TYPE 1\n";
  if (columns.id) defines += "#define HAS_ID 1\n";
  if (columns.links) defines += "#define HAS_LINKS 1\n";
  if (columns.hermite) defines += "#define HAS_HERMITE 1\n";
  if (columns.cut) defines += "#define HAS_CUT 1\n";
  GlProgram program = BuildGlProgram(
      "compute splat", {{GL_COMPUTE_SHADER,
                         {defines.c_str(), shaders::kShaderSplatCommon, shaders::kShaderSplatPoint, shaders::kShaderSplatAccumulate,
                          shaders::kShaderSplatComp}}});
  return programs_.emplace(key, std::move(program)).first->second;
}

bool ComputeSplatter::CanSplat(const ComputeColumns& columns) const {
  return StorageBuffersOf(columns) <= max_storage_buffers_;
}

void ComputeSplatter::Splat(const GpuBlockArena& arena, std::uint32_t pool, std::uint32_t first_draw,
                            std::uint32_t draw_count, std::uint32_t points, std::uint32_t base,
                            const ComputeColumns& columns) {
  if (points == 0 || draw_count == 0) return;
  const GlProgram& program = ProgramFor(columns);
  const std::uint32_t capacity = arena.capacity(pool);
  const std::vector<GpuBlockArena::ColumnBuffer> buffers = arena.column_buffers(pool);
  for (ColumnId id : ColumnsRead(columns)) {
    const auto it = std::find_if(buffers.begin(), buffers.end(), [&](const auto& b) { return b.id == id; });
    if (it == buffers.end()) {
      glBindBufferBase(GL_SHADER_STORAGE_BUFFER, ColumnBinding(id), absent_column_.get());
      continue;
    }
    // From the base on, as far as a dispatch may span (or the pool's end).
    const std::uint64_t offset = std::uint64_t{base} * it->stride;
    const std::uint64_t size = std::min(std::uint64_t{capacity} * it->stride - offset,
                                        std::uint64_t{max_span_points_} * it->stride);
    glBindBufferRange(GL_SHADER_STORAGE_BUFFER, ColumnBinding(id), it->buffer, static_cast<GLintptr>(offset),
                      static_cast<GLsizeiptr>(size));
  }
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kAccumulationBinding, accumulation_.get());
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kLargeBlobsBinding, large_blobs_.get());
  glUseProgram(program.get());
  glProgramUniform1ui(program.get(), Location(program, "u_first_draw"), first_draw);
  glProgramUniform1ui(program.get(), Location(program, "u_draw_count"), draw_count);
  glProgramUniform1ui(program.get(), Location(program, "u_points"), points);
  glProgramUniform1ui(program.get(), Location(program, "u_base"), base);
  glProgramUniform1ui(program.get(), Location(program, "u_id_words"), arena.id_offsets(pool) ? 1u : 2u);
  glProgramUniform1f(program.get(), Location(program, "u_compute_radius"), compute_radius_);
  glProgramUniform2i(program.get(), Location(program, "u_target_size"), width_, height_);
  const GLuint groups = std::min<GLuint>(kMaxGroups, (points + 255) / 256);
  glDispatchCompute(groups, 1, 1);
  pending_ = true;
  SplatLargeBlobs();
  CheckGlError("splatting blocks by compute");
}

void ComputeSplatter::SplatLargeBlobs() {
  glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
  glUseProgram(large_program_.get());
  glProgramUniform2i(large_program_.get(), Location(large_program_, "u_target_size"), width_, height_);
  glDispatchCompute(kLargeBlobGroups, 1, 1);
  // The count back to 0 for the next dispatch, once this one has read it.
  glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
  const std::uint32_t zero = 0;
  glClearNamedBufferSubData(large_blobs_.get(), GL_R32UI, 0, 4, GL_RED_INTEGER, GL_UNSIGNED_INT, &zero);
}

void ComputeSplatter::Resolve(GLuint texture) {
  if (!pending_) return;
  glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_SHADER_IMAGE_ACCESS_BARRIER_BIT | GL_FRAMEBUFFER_BARRIER_BIT);
  glUseProgram(resolve_.get());
  glBindImageTexture(0, texture, 0, GL_FALSE, 0, GL_READ_WRITE, GL_RGBA32F);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kAccumulationBinding, accumulation_.get());
  glProgramUniform2i(resolve_.get(), Location(resolve_, "u_size"), width_, height_);
  glDispatchCompute(static_cast<GLuint>((width_ + 15) / 16), static_cast<GLuint>((height_ + 15) / 16), 1);
  glMemoryBarrier(GL_SHADER_IMAGE_ACCESS_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT | GL_TEXTURE_UPDATE_BARRIER_BIT |
                  GL_FRAMEBUFFER_BARRIER_BIT | GL_SHADER_STORAGE_BARRIER_BIT);
  pending_ = false;
  CheckGlError("resolving the compute path's accumulation");
}

}  // namespace octocosm
