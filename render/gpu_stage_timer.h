// GPU time of a frame's stages, from timestamp queries (GL_TIMESTAMP) that
// the GPU writes as it reaches each mark. Results are collected without
// waiting whenever the GPU has finished a frame's marks, usually a frame or
// two after it was drawn, so timing never makes the CPU wait for the GPU
// inside a render loop; a one-shot renderer that has read its picture back
// may wait, since the GPU is then done anyway.
#pragma once

#include <array>
#include <cstdint>
#include <optional>

#include "render/gl_objects.h"

namespace octocosm {

struct GpuStageTimes {
  double draw_ms = 0;      // from the frame's start (the clear) to its measuring: the blobs
  double measure_ms = 0;   // the image statistics' compute passes (not the wait for their result)
  double tone_map_ms = 0;  // tone mapping into the display image or the window
};

class GpuStageTimer {
 public:
  enum class Mark { kFrameStart, kMeasureStart, kMeasureEnd, kToneMapStart, kToneMapEnd };

  GpuStageTimer();
  GpuStageTimer(const GpuStageTimer&) = delete;
  GpuStageTimer& operator=(const GpuStageTimer&) = delete;
  ~GpuStageTimer();

  // Records a mark of the current frame; kFrameStart begins a new frame. A
  // mark given twice in a frame keeps the later one.
  void Record(Mark mark);
  // The times of the newest frame whose marks the GPU has all written;
  // `wait`: wait for the newest frame with every mark recorded.
  std::optional<GpuStageTimes> Latest(bool wait);

 private:
  static constexpr int kMarks = 5;
  static constexpr int kFrames = 4;  // frames in flight before a set of queries is reused
  struct FrameQueries {
    std::array<GLuint, kMarks> queries{};
    std::array<bool, kMarks> recorded{};
    std::uint64_t serial = 0;  // 0: nothing recorded since the set was last collected
  };
  bool Complete(const FrameQueries& frame) const;
  bool Available(const FrameQueries& frame) const;
  GpuStageTimes Read(const FrameQueries& frame) const;

  std::array<FrameQueries, kFrames> frames_;
  int current_ = -1;
  std::uint64_t next_serial_ = 1;
  std::uint64_t latest_serial_ = 0;
  std::optional<GpuStageTimes> latest_;
};

}  // namespace octocosm
