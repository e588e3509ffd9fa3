#include "render/gpu_stage_timer.h"

namespace octocosm {

GpuStageTimer::GpuStageTimer() {
  for (FrameQueries& frame : frames_) glCreateQueries(GL_TIMESTAMP, kMarks, frame.queries.data());
  CheckGlError("creating timestamp queries");
}

GpuStageTimer::~GpuStageTimer() {
  for (FrameQueries& frame : frames_) glDeleteQueries(kMarks, frame.queries.data());
}

void GpuStageTimer::Record(Mark mark) {
  if (mark == Mark::kFrameStart) {
    // The set reused is the oldest; its result, if the GPU has it, is kept
    // first, and if not it is dropped rather than waited for.
    current_ = (current_ + 1) % kFrames;
    Latest(false);
    FrameQueries& frame = frames_[static_cast<std::size_t>(current_)];
    frame.recorded.fill(false);
    frame.serial = next_serial_++;
  }
  if (current_ < 0) return;  // marks before the first frame start
  FrameQueries& frame = frames_[static_cast<std::size_t>(current_)];
  const std::size_t index = static_cast<std::size_t>(mark);
  glQueryCounter(frame.queries[index], GL_TIMESTAMP);
  frame.recorded[index] = true;
}

bool GpuStageTimer::Complete(const FrameQueries& frame) const {
  if (frame.serial == 0) return false;
  for (const bool recorded : frame.recorded) {
    if (!recorded) return false;
  }
  return true;
}

bool GpuStageTimer::Available(const FrameQueries& frame) const {
  GLuint available = 0;
  glGetQueryObjectuiv(frame.queries[kMarks - 1], GL_QUERY_RESULT_AVAILABLE, &available);
  return available != 0;  // timestamps complete in order: the last mark's implies the others'
}

GpuStageTimes GpuStageTimer::Read(const FrameQueries& frame) const {
  std::array<GLuint64, kMarks> t{};
  for (int m = 0; m < kMarks; ++m) glGetQueryObjectui64v(frame.queries[static_cast<std::size_t>(m)], GL_QUERY_RESULT, &t[static_cast<std::size_t>(m)]);
  const auto ms = [&](int from, int to) {
    const GLuint64 a = t[static_cast<std::size_t>(from)], b = t[static_cast<std::size_t>(to)];
    return b > a ? static_cast<double>(b - a) * 1e-6 : 0.0;
  };
  // Between the measure's end and the tone map's start the GPU may wait for
  // the CPU (a one-shot frame reads the statistics first): counted in none.
  return {ms(0, 1), ms(1, 2), ms(3, 4)};
}

std::optional<GpuStageTimes> GpuStageTimer::Latest(bool wait) {
  // The newest complete frame that is newer than what was collected.
  const FrameQueries* newest = nullptr;
  for (const FrameQueries& frame : frames_) {
    if (!Complete(frame) || frame.serial <= latest_serial_) continue;
    if (!wait && !Available(frame)) continue;
    if (newest == nullptr || frame.serial > newest->serial) newest = &frame;
  }
  if (newest != nullptr) {
    latest_ = Read(*newest);  // waits, when `wait`, for the GPU to write the marks
    latest_serial_ = newest->serial;
  }
  return latest_;
}

}  // namespace octocosm
