#include "render/splat_renderer.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <string>
#include <vector>

#include "base/error.h"
#include "render/color_maps.h"
#include "render/render_shaders.h"
#include "render/splat_kernel.h"

namespace octocosm {
namespace {

constexpr std::size_t kStatisticsWords = 4 + 2 * kHistogramBins;

GLint Location(const GlProgram& program, const char* name) { return glGetUniformLocation(program.get(), name); }

void SetMap(const GlProgram& program, const char* name, ColorMapId id) {
  const auto& knots = ColorMapKnots(id);
  glProgramUniform3fv(program.get(), Location(program, name), kColorMapKnots, knots[0].data());
}

// Sets `out` to a + shift - b, in double before the float.
void SetDifference(float (&out)[4], const std::array<double, 3>& a, double shift, const std::array<double, 3>& b) {
  for (std::size_t i = 0; i < 3; ++i) out[i] = static_cast<float>(a[i] + shift - b[i]);
  out[3] = 0;
}

float Unordered(std::uint32_t u) {
  return std::bit_cast<float>((u & 0x80000000u) != 0 ? (u & 0x7FFFFFFFu) : ~u);
}

}  // namespace

SplatRenderer::SplatRenderer() {
  splat_ = BuildGlProgram(
      "splat", {{GL_VERTEX_SHADER, {shaders::kShaderSplatCommon, shaders::kShaderSplatPoint, shaders::kShaderSplatVert}},
                {GL_FRAGMENT_SHADER, {shaders::kShaderSplatCommon, shaders::kShaderSplatFrag}}});
  tone_map_ = BuildGlProgram("tone map", {{GL_VERTEX_SHADER, {shaders::kShaderFullscreenVert}},
                                          {GL_FRAGMENT_SHADER, {shaders::kShaderToneMapFrag}}});
  statistics_ = BuildGlProgram("image statistics", {{GL_COMPUTE_SHADER, {shaders::kShaderImageStatsComp}}});

  GLuint vao = 0;
  glCreateVertexArrays(1, &vao);
  empty_vao_ = GlVertexArray(vao);
  frame_uniforms_ = MakeGlBuffer(sizeof(FrameUniforms), nullptr, GL_DYNAMIC_STORAGE_BIT);
  cut_counter_ = MakeGlBuffer(4, nullptr, GL_DYNAMIC_STORAGE_BIT);
  statistics_work_ = MakeGlBuffer(kStatisticsWords * 4, nullptr, GL_DYNAMIC_STORAGE_BIT);
  constexpr GLbitfield kMapped = GL_MAP_READ_BIT | GL_MAP_PERSISTENT_BIT | GL_MAP_COHERENT_BIT;
  for (PendingStatistics& pending : measures_) {
    pending.buffer = MakeGlBuffer(kStatisticsWords * 4, nullptr, kMapped);
    pending.words = static_cast<const std::uint32_t*>(
        glMapNamedBufferRange(pending.buffer.get(), 0, static_cast<GLsizeiptr>(kStatisticsWords * 4), kMapped));
    if (pending.words == nullptr) throw Error::NotSupported("OpenGL", "cannot map the image statistics' buffer");
  }
  const SelectionSet empty({});
  no_selection_ = MakeGlBuffer(empty.words().size() * 4, empty.words().data(), 0);

  GLfloat range[2] = {1, 1};
  glGetFloatv(GL_POINT_SIZE_RANGE, range);
  // A sprite of side SpriteSize(R) must fit the largest point size.
  max_blob_radius_ = std::max(kMinBlobRadius, std::floor((double{range[1]} - kSpriteGuard) / 2));
  compute_supported_ = ComputeSplatter::Supported();
  const auto* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  const std::string renderer_name = renderer != nullptr ? renderer : "";
  const bool software = renderer_name.find("llvmpipe") != std::string::npos ||
                        renderer_name.find("softpipe") != std::string::npos ||
                        renderer_name.find("SWR") != std::string::npos;
  compute_preferred_ = compute_supported_ && !software;
  CheckGlError("setting up the splat renderer");
}

const char* SplatPathName(SplatPath path) {
  switch (path) {
    case SplatPath::kRaster: return "raster";
    case SplatPath::kCompute: return "compute";
    case SplatPath::kAuto: return "auto";
  }
  return "?";
}

SplatPath ParseSplatPath(const std::string& name) {
  for (SplatPath path : {SplatPath::kRaster, SplatPath::kCompute, SplatPath::kAuto}) {
    if (name == SplatPathName(path)) return path;
  }
  throw Error::InvalidArgument("unknown splat path '" + name + "' (raster, compute or auto)");
}

void SplatRenderer::SetLargeBlobCapacity(std::uint32_t blobs) {
  if (!compute_supported_) return;
  if (!compute_) compute_ = std::make_unique<ComputeSplatter>();
  compute_->set_large_blob_capacity(blobs);
}

SplatRenderer::~SplatRenderer() {
  for (PendingStatistics& pending : measures_) {
    if (pending.fence != nullptr) glDeleteSync(pending.fence);
  }
}

void SplatRenderer::Allocate(RenderTarget& target, GLenum format, int width, int height, const char* what) {
  if (target.width == width && target.height == height) return;
  target = RenderTarget();
  GLuint texture = 0;
  glCreateTextures(GL_TEXTURE_2D, 1, &texture);
  target.texture = GlTexture(texture);
  glTextureStorage2D(texture, 1, format, width, height);
  // texelFetch needs a complete texture: no mipmaps, so no mipmap filter.
  glTextureParameteri(texture, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTextureParameteri(texture, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  GLuint fbo = 0;
  glCreateFramebuffers(1, &fbo);
  target.framebuffer = GlFramebuffer(fbo);
  glNamedFramebufferTexture(fbo, GL_COLOR_ATTACHMENT0, texture, 0);
  if (glCheckNamedFramebufferStatus(fbo, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    throw Error::NotSupported("OpenGL", std::string(what) + " of " + std::to_string(width) + "x" +
                                            std::to_string(height) + " is not supported as a framebuffer");
  }
  CheckGlError(std::string("allocating ") + what);
  target.width = width;
  target.height = height;
}

void SplatRenderer::BeginFrame(const RenderView& view, const FrameSettings& settings) {
  if (view.max_blob_radius() > max_blob_radius_) {
    throw Error::InvalidArgument("a blob radius of " + std::to_string(view.max_blob_radius()) +
                                 " pixels exceeds what this OpenGL draws (" + std::to_string(max_blob_radius_) + ")");
  }
  if (!(settings.mass_unit > 0) || !std::isfinite(settings.mass_unit)) {
    throw Error::InvalidArgument("the mass unit must be finite and > 0");
  }
  if (!(settings.t >= 0 && settings.t <= 1)) throw Error::InvalidArgument("interpolation time must be in [0, 1]");
  if (!(settings.compute_radius >= 0) || !std::isfinite(settings.compute_radius)) {
    throw Error::InvalidArgument("the compute path's blob radius must be finite and >= 0");
  }
  if (!(settings.cut_threshold >= 0) || !std::isfinite(settings.cut_threshold)) {
    throw Error::InvalidArgument("the cluster cut's threshold must be finite and >= 0");
  }
  if (!(settings.box_size >= 0) || !std::isfinite(settings.box_size) ||
      !std::all_of(settings.box_origin.begin(), settings.box_origin.end(), [](double x) { return std::isfinite(x); })) {
    throw Error::InvalidArgument("the periodic box must be finite, of size >= 0");
  }
  margin_ = GuardMargin(view.max_blob_radius());
  const int tw = view.width() + 2 * margin_, th = view.height() + 2 * margin_;
  // A frame left unfinished: its draws go where they were meant to.
  Flush();
  Resolve();
  records_.clear();
  records_uploaded_ = 0;
  commands_used_ = 0;
  Allocate(accumulation_, GL_RGBA32F, tw, th, "the accumulation buffer");
  compute_frame_ = false;
  if (settings.path == SplatPath::kCompute ? compute_supported_
                                           : settings.path == SplatPath::kAuto && compute_preferred_) {
    if (!compute_) compute_ = std::make_unique<ComputeSplatter>();
    compute_->set_compute_radius(settings.compute_radius);
    compute_frame_ = compute_->Prepare(tw, th);
  }
  in_frame_ = true;
  width_ = view.width();
  height_ = view.height();
  camera_position_ = view.camera().position;
  settings_ = settings;
  copy_direction_ = 1;
  copy_weight_ = 1;

  auto put3 = [](float (&dst)[4], const std::array<double, 3>& v) {
    for (int a = 0; a < 3; ++a) dst[a] = static_cast<float>(v[static_cast<std::size_t>(a)]);
    dst[3] = 0;
  };
  put3(uniforms_.right, view.right());
  put3(uniforms_.up, view.up());
  put3(uniforms_.forward, view.forward());
  uniforms_.viewport[0] = static_cast<float>(view.width());
  uniforms_.viewport[1] = static_cast<float>(view.height());
  uniforms_.viewport[2] = static_cast<float>(margin_);
  uniforms_.viewport[3] = static_cast<float>(view.focal_pixels());
  uniforms_.limits[0] = static_cast<float>(view.camera().near);
  uniforms_.limits[1] = static_cast<float>(std::min(view.camera().far, 1e38));
  uniforms_.limits[2] = static_cast<float>(view.max_blob_radius());
  uniforms_.limits[3] = static_cast<float>(1 / settings.mass_unit);
  uniforms_.modes[0] = static_cast<std::int32_t>(settings.color);
  uniforms_.modes[1] = static_cast<std::int32_t>(settings.interpolation);
  uniforms_.time[0] = static_cast<float>(settings.t);
  uniforms_.time[2] = static_cast<float>(settings.hermite_scale);
  uniforms_.wrap[0] = settings.box_size > 0 && settings.interpolation != Interpolation::kNone ? 1 : 0;
  const double half_pixel = 0.5 / view.focal_pixels();
  uniforms_.cut[0] = static_cast<float>(settings.cut_threshold);
  uniforms_.cut[1] = static_cast<float>(half_pixel * half_pixel);
  uniforms_.cut[2] = settings.count_cut ? 1.0f : 0.0f;
  const std::uint32_t no_points = 0;
  glClearNamedBufferSubData(cut_counter_.get(), GL_R32UI, 0, 4, GL_RED_INTEGER, GL_UNSIGNED_INT, &no_points);
  glBindBufferBase(GL_ATOMIC_COUNTER_BUFFER, 0, cut_counter_.get());
  highlight_only_ = false;
  SetSelection(nullptr);
  SetCopy(1, 1);

  glBindFramebuffer(GL_FRAMEBUFFER, accumulation_.framebuffer.get());
  glViewport(0, 0, accumulation_.width, accumulation_.height);
  const float zero[4] = {0, 0, 0, 0};
  glClearNamedFramebufferfv(accumulation_.framebuffer.get(), GL_COLOR, 0, zero);
  timer_.Record(GpuStageTimer::Mark::kFrameStart);
}

void SplatRenderer::UploadFrameUniforms() {
  draw_state_set_ = false;
  uniforms_.modes[2] = highlight_only_ ? 2 : selection_on_ ? 1 : 0;
  uniforms_.modes[3] = copy_direction_;
  uniforms_.time[1] = static_cast<float>(copy_weight_);
  glNamedBufferSubData(frame_uniforms_.get(), 0, sizeof uniforms_, &uniforms_);
}

void SplatRenderer::SetCopy(int direction, double weight) {
  Flush();
  copy_direction_ = direction >= 0 ? 1 : -1;
  copy_weight_ = weight;
  UploadFrameUniforms();
}

void SplatRenderer::SetSelection(const SelectionSet* selection) {
  Flush();
  selection_on_ = selection != nullptr && selection->size() > 0 && selection->buffer() != 0;
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, selection_on_ ? selection->buffer() : no_selection_.get());
  UploadFrameUniforms();
}

void SplatRenderer::SetHighlightOnly(bool on) {
  Flush();
  highlight_only_ = on;
  UploadFrameUniforms();
}

void SplatRenderer::Draw(const GpuBlock& block, std::uint32_t first, std::uint32_t count, CutRole cut) {
  if (!in_frame_) throw Error::InvalidArgument("SplatRenderer::Draw outside a frame (call BeginFrame first)");
  if (count == 0) return;
  if (first > block.point_count() || count > block.point_count() - first) {
    throw Error::InvalidArgument("SplatRenderer::Draw: points [" + std::to_string(first) + ", " +
                                 std::to_string(first + count) + ") are outside a block of " +
                                 std::to_string(block.point_count()));
  }
  const GpuBlockArena::Placement& placement = block.placement();
  DrawRecord record{};
  const NodeCube& node = block.node();
  SetDifference(record.origin, node.origin, 0, camera_position_);
  if (uniforms_.wrap[0] != 0) {
    const double size = settings_.box_size;
    SetDifference(record.box_low, settings_.box_origin, 0, node.origin);
    SetDifference(record.box_high, settings_.box_origin, size, node.origin);
    SetDifference(record.origin_below, node.origin, -size, camera_position_);
    SetDifference(record.origin_above, node.origin, size, camera_position_);
  }
  record.block[0] = placement.slot;
  if (cut != CutRole::kNone) {
    if (!block.has_cut()) throw Error::InvalidArgument("SplatRenderer::Draw: a cut role for a block uploaded without the cut's entries");
    constexpr std::uint32_t kApplies = 1, kFinal = 2, kHasParent = 4;  // kCut* of shaders/splat_point.glsl
    record.cut[0] = kApplies | (cut == CutRole::kCutFinal ? kFinal : 0) | (block.has_parent() ? kHasParent : 0);
    // As the parent's own draw sets its origin: the same doubles, the same float.
    SetDifference(record.parent_origin, block.parent_node().origin, 0, camera_position_);
  }
  if (queued_.size() <= placement.pool) queued_.resize(placement.pool + 1);
  queued_[placement.pool].push_back({record, placement.first + first, count});
}

void SplatRenderer::Flush() {
  if (std::all_of(queued_.begin(), queued_.end(), [](const auto& pool) { return pool.empty(); })) return;
  glBindFramebuffer(GL_FRAMEBUFFER, accumulation_.framebuffer.get());
  glViewport(0, 0, accumulation_.width, accumulation_.height);
  if (!draw_state_set_) {
    // Once per frame, or after another pass: state changes between draws
    // make drivers (llvmpipe among them) flush the work queued so far.
    glEnable(GL_BLEND);
    glBlendEquation(GL_FUNC_ADD);
    glBlendFunc(GL_ONE, GL_ONE);
    glDisable(GL_DEPTH_TEST);
    glEnable(GL_PROGRAM_POINT_SIZE);
    glUseProgram(splat_.get());
    glBindBufferBase(GL_UNIFORM_BUFFER, 0, frame_uniforms_.get());
    draw_state_set_ = true;
  }
  if (compute_frame_) {
    // Pools whose columns need more storage buffers than a compute shader
    // may bind are drawn by the raster path, into the same image.
    std::vector<std::vector<QueuedDraw>> compute_queued(queued_.size());
    for (std::uint32_t pool = 0; pool < queued_.size(); ++pool) {
      if (!queued_[pool].empty() && compute_->CanSplat(ComputeColumnsOf(pool))) std::swap(compute_queued[pool], queued_[pool]);
    }
    if (std::any_of(queued_.begin(), queued_.end(), [](const auto& pool) { return !pool.empty(); })) FlushRaster();
    std::swap(queued_, compute_queued);
    FlushCompute();
  } else {
    FlushRaster();
  }
  CheckGlError("drawing blocks");
}

void SplatRenderer::UploadRecords() {
  // The frame's draw records so far: new ones appended, or all of them into
  // a larger buffer (draws issued earlier keep the one they read).
  arena_.ReserveDrawIndices(records_.size());
  if (records_.size() > records_capacity_) {
    records_capacity_ = std::max({records_.size(), 2 * records_capacity_, std::size_t{1024}});
    records_buffer_ = MakeGlBuffer(records_capacity_ * sizeof(DrawRecord), nullptr, GL_DYNAMIC_STORAGE_BIT);
    records_uploaded_ = 0;
  }
  glNamedBufferSubData(records_buffer_.get(), static_cast<GLintptr>(records_uploaded_ * sizeof(DrawRecord)),
                       static_cast<GLsizeiptr>((records_.size() - records_uploaded_) * sizeof(DrawRecord)),
                       records_.data() + records_uploaded_);
  records_uploaded_ = records_.size();
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, arena_.parameters());
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 4, records_buffer_.get());
}

void SplatRenderer::FlushRaster() {
  // One indirect command per draw, its base instance its record.
  commands_.resize(queued_.size());
  std::size_t pending = 0;
  for (std::size_t pool = 0; pool < queued_.size(); ++pool) {
    for (const QueuedDraw& q : queued_[pool]) {
      commands_[pool].push_back({q.count, 1, q.first, static_cast<GLuint>(records_.size())});
      records_.push_back(q.record);
    }
    pending += queued_[pool].size();
    queued_[pool].clear();
  }
  UploadRecords();
  if (commands_used_ + pending > commands_capacity_) {
    commands_capacity_ = std::max({pending, 2 * commands_capacity_, std::size_t{1024}});
    commands_buffer_ = MakeGlBuffer(commands_capacity_ * sizeof(DrawCommand), nullptr, GL_DYNAMIC_STORAGE_BIT);
    commands_used_ = 0;
  }
  glBindBuffer(GL_DRAW_INDIRECT_BUFFER, commands_buffer_.get());
  for (std::uint32_t pool = 0; pool < commands_.size(); ++pool) {
    std::vector<DrawCommand>& commands = commands_[pool];
    if (commands.empty()) continue;
    const std::size_t offset = commands_used_ * sizeof(DrawCommand);
    glNamedBufferSubData(commands_buffer_.get(), static_cast<GLintptr>(offset),
                         static_cast<GLsizeiptr>(commands.size() * sizeof(DrawCommand)), commands.data());
    glBindVertexArray(arena_.vertex_array(pool));
    glMultiDrawArraysIndirect(GL_POINTS, reinterpret_cast<const void*>(offset), static_cast<GLsizei>(commands.size()), 0);
    commands_used_ += commands.size();
    commands.clear();
  }
}

void SplatRenderer::FlushCompute() {
  // One dispatch per pool (more where its draws span more points than one
  // storage binding holds), its draws' records contiguous and in pool order.
  struct Dispatch {
    std::uint32_t pool, first_draw, draw_count, points, base;
  };
  std::vector<Dispatch> dispatches;
  const std::uint32_t align = compute_->base_alignment(), span = compute_->max_span_points();
  for (std::uint32_t pool = 0; pool < queued_.size(); ++pool) {
    std::vector<QueuedDraw>& queued = queued_[pool];
    std::sort(queued.begin(), queued.end(), [](const QueuedDraw& a, const QueuedDraw& b) { return a.first < b.first; });
    for (std::size_t i = 0; i < queued.size();) {
      Dispatch d{pool, static_cast<std::uint32_t>(records_.size()), 0, 0, queued[i].first / align * align};
      while (i < queued.size() && std::uint64_t{queued[i].first} + queued[i].count - d.base <= span) {
        DrawRecord record = queued[i].record;
        record.block[1] = queued[i].first;
        record.block[2] = queued[i].count;
        record.block[3] = d.points;
        records_.push_back(record);
        d.points += queued[i].count;
        ++d.draw_count;
        ++i;
      }
      if (d.draw_count == 0) {
        throw Error::NotSupported("OpenGL", "a block of " + std::to_string(queued[i].count) +
                                                " points exceeds what one storage buffer of the compute path holds");
      }
      dispatches.push_back(d);
    }
    queued.clear();
  }
  UploadRecords();
  for (const Dispatch& d : dispatches) {
    compute_->Splat(arena_, d.pool, d.first_draw, d.draw_count, d.points, d.base, ComputeColumnsOf(d.pool));
  }
  draw_state_set_ = false;  // the compute path bound its own programs
}

ComputeColumns SplatRenderer::ComputeColumnsOf(std::uint32_t pool) const {
  const int mode = uniforms_.modes[0], interpolation = uniforms_.modes[1];
  ComputeColumns columns;
  columns.velocity = (mode >= 1 && mode <= 3) || interpolation == 2;
  columns.dispersion = mode >= 1 && mode <= 3;
  columns.type = mode == 4;
  columns.id = uniforms_.modes[2] == 1;
  columns.links = interpolation != 0;
  columns.hermite = interpolation == 2;
  const std::vector<GpuBlockArena::ColumnBuffer> buffers = arena_.column_buffers(pool);
  columns.cut = std::any_of(buffers.begin(), buffers.end(),
                            [](const GpuBlockArena::ColumnBuffer& b) { return b.id == ColumnId::kRefineBound; });
  return columns;
}

std::uint64_t SplatRenderer::CutPointsCounted() {
  Flush();
  glMemoryBarrier(GL_ATOMIC_COUNTER_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
  std::uint32_t count = 0;
  glGetNamedBufferSubData(cut_counter_.get(), 0, 4, &count);
  CheckGlError("reading the cluster cut's count");
  return count;
}

void SplatRenderer::Resolve() {
  if (!compute_ || !compute_->pending()) return;
  compute_->Resolve(accumulation_.texture.get());
  draw_state_set_ = false;
}

void SplatRenderer::StartMeasure() {
  Flush();
  Resolve();
  draw_state_set_ = false;
  timer_.Record(GpuStageTimer::Mark::kMeasureStart);
  PendingStatistics& pending = measures_[measure_next_];
  measure_next_ = (measure_next_ + 1) % measures_.size();
  Collect(pending, true);  // the oldest in flight: its buffer is about to be written again
  std::vector<std::uint32_t> words(kStatisticsWords, 0);
  words[1] = 0xFFFFFFFFu;  // the ordered minimum starts at the largest value
  glNamedBufferSubData(statistics_work_.get(), 0, static_cast<GLsizeiptr>(words.size() * 4), words.data());
  glUseProgram(statistics_.get());
  glBindTextureUnit(0, accumulation_.texture.get());
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 2, statistics_work_.get());
  glProgramUniform2i(statistics_.get(), Location(statistics_, "u_offset"), margin_, margin_);
  glProgramUniform2i(statistics_.get(), Location(statistics_, "u_size"), width_, height_);
  glProgramUniform1i(statistics_.get(), Location(statistics_, "u_color_mode"), static_cast<GLint>(settings_.color));
  glProgramUniform1f(statistics_.get(), Location(statistics_, "u_mass_unit"), static_cast<float>(settings_.mass_unit));
  glMemoryBarrier(GL_FRAMEBUFFER_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
  for (int pass = 0; pass < 2; ++pass) {
    glProgramUniform1i(statistics_.get(), Location(statistics_, "u_pass"), pass);
    glDispatchCompute(static_cast<GLuint>((width_ + 15) / 16), static_cast<GLuint>((height_ + 15) / 16), 1);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
  }
  glCopyNamedBufferSubData(statistics_work_.get(), pending.buffer.get(), 0, 0,
                           static_cast<GLsizeiptr>(kStatisticsWords * 4));
  timer_.Record(GpuStageTimer::Mark::kMeasureEnd);
  // The copy reaches the mapping before the fence signals.
  glMemoryBarrier(GL_CLIENT_MAPPED_BUFFER_BARRIER_BIT);
  pending.fence = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
  pending.color = settings_.color;
  pending.serial = ++measures_started_;
  CheckGlError("measuring the image");
}

bool SplatRenderer::Collect(PendingStatistics& pending, bool wait) {
  if (pending.fence == nullptr) return false;
  for (;;) {
    const GLenum status = glClientWaitSync(pending.fence, GL_SYNC_FLUSH_COMMANDS_BIT, wait ? 1'000'000'000 : 0);
    if (status == GL_ALREADY_SIGNALED || status == GL_CONDITION_SATISFIED) break;
    if (status == GL_WAIT_FAILED) throw Error::NotSupported("OpenGL", "waiting for the image statistics failed");
    if (!wait) return false;
  }
  glDeleteSync(pending.fence);
  pending.fence = nullptr;
  if (pending.serial <= measures_collected_) return true;
  const std::uint32_t* words = pending.words;
  ImageStatistics s;
  s.max_density = std::bit_cast<float>(words[0]);
  if (s.max_density > 0 && pending.color != ColorMode::kDensity) {
    s.attribute_min = Unordered(words[1]);
    s.attribute_max = Unordered(words[2]);
  }
  std::copy_n(words + 4, kHistogramBins, s.density.begin());
  std::copy_n(words + 4 + kHistogramBins, kHistogramBins, s.attribute.begin());
  latest_statistics_ = s;
  measures_collected_ = pending.serial;
  return true;
}

std::optional<ImageStatistics> SplatRenderer::LatestStatistics(bool wait) {
  if (wait) {
    Collect(measures_[(measure_next_ + measures_.size() - 1) % measures_.size()], true);  // the newest started
    return latest_statistics_;
  }
  // Oldest first, so that the newest finished one is kept.
  for (std::size_t i = 0; i < measures_.size(); ++i) Collect(measures_[(measure_next_ + i) % measures_.size()], false);
  return latest_statistics_;
}

ImageStatistics SplatRenderer::Measure() {
  StartMeasure();
  return *LatestStatistics(true);
}

ImageStatistics SplatRenderer::MeasureLate() {
  StartMeasure();
  const std::optional<ImageStatistics> latest = LatestStatistics();
  return latest ? *latest : *LatestStatistics(true);
}

void SplatRenderer::ToneMap(const ToneMapParameters& p, int x, int y) {
  Flush();
  Resolve();
  draw_state_set_ = false;
  const GLuint program = tone_map_.get();
  glProgramUniform2i(program, Location(tone_map_, "u_offset"), margin_, margin_);
  glProgramUniform2i(program, Location(tone_map_, "u_viewport_origin"), x, y);
  glProgramUniform1f(program, Location(tone_map_, "u_mass_unit"), static_cast<float>(settings_.mass_unit));
  glProgramUniform1i(program, Location(tone_map_, "u_curve"), p.curve == ToneCurve::kAsinh ? 1 : 0);
  glProgramUniform1f(program, Location(tone_map_, "u_exposure"), static_cast<float>(p.exposure));
  glProgramUniform1f(program, Location(tone_map_, "u_floor"), static_cast<float>(p.floor));
  glProgramUniform1i(program, Location(tone_map_, "u_color_mode"), static_cast<GLint>(p.color));
  glProgramUniform1f(program, Location(tone_map_, "u_attribute_low"), static_cast<float>(p.attribute_low));
  glProgramUniform1f(program, Location(tone_map_, "u_attribute_high"), static_cast<float>(p.attribute_high));
  glProgramUniform3f(program, Location(tone_map_, "u_highlight"), static_cast<float>(p.highlight[0]),
                     static_cast<float>(p.highlight[1]), static_cast<float>(p.highlight[2]));
  SetMap(tone_map_, "u_density_map", p.density_map);
  SetMap(tone_map_, "u_attribute_map", p.attribute_map);
  glDisable(GL_BLEND);
  glMemoryBarrier(GL_FRAMEBUFFER_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
  timer_.Record(GpuStageTimer::Mark::kToneMapStart);
  glUseProgram(program);
  glBindVertexArray(empty_vao_.get());
  glBindTextureUnit(0, accumulation_.texture.get());
  glDrawArrays(GL_TRIANGLES, 0, 3);
  timer_.Record(GpuStageTimer::Mark::kToneMapEnd);
  CheckGlError("tone mapping");
}

void SplatRenderer::ToneMapToImage(const ToneMapParameters& parameters) {
  Flush();
  Allocate(display_, GL_RGBA8, width_, height_, "the display image");
  glBindFramebuffer(GL_FRAMEBUFFER, display_.framebuffer.get());
  glViewport(0, 0, width_, height_);
  ToneMap(parameters, 0, 0);
}

void SplatRenderer::ToneMapToViewport(const ToneMapParameters& parameters, int x, int y) {
  Flush();
  glViewport(x, y, width_, height_);
  ToneMap(parameters, x, y);
}

HdrImage SplatRenderer::ReadHdr() {
  Flush();
  Resolve();
  HdrImage image{width_, height_, {}};
  std::vector<float> texels(4 * static_cast<std::size_t>(width_) * height_);
  glMemoryBarrier(GL_FRAMEBUFFER_BARRIER_BIT | GL_TEXTURE_UPDATE_BARRIER_BIT);
  glGetTextureSubImage(accumulation_.texture.get(), 0, margin_, margin_, 0, width_, height_, 1, GL_RGBA, GL_FLOAT,
                       static_cast<GLsizei>(texels.size() * sizeof(float)), texels.data());
  CheckGlError("reading the accumulation buffer");
  image.rgba.resize(texels.size());
  for (std::size_t i = 0; i < texels.size(); ++i) image.rgba[i] = texels[i] * settings_.mass_unit;
  return image;
}

RgbImage SplatRenderer::ReadDisplay() {
  RgbImage image{width_, height_, {}};
  std::vector<std::uint8_t> rgba(4 * static_cast<std::size_t>(width_) * height_);
  glGetTextureSubImage(display_.texture.get(), 0, 0, 0, 0, width_, height_, 1, GL_RGBA, GL_UNSIGNED_BYTE,
                       static_cast<GLsizei>(rgba.size()), rgba.data());
  CheckGlError("reading the display image");
  image.rgb.resize(3 * static_cast<std::size_t>(width_) * height_);
  for (std::size_t p = 0; p < static_cast<std::size_t>(width_) * height_; ++p) {
    for (int c = 0; c < 3; ++c) image.rgb[3 * p + static_cast<std::size_t>(c)] = rgba[4 * p + static_cast<std::size_t>(c)];
  }
  return image;
}

void SplatRenderer::Finish() {
  Flush();
  Resolve();
  glFinish();
}

}  // namespace octocosm
