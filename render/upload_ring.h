// Uploads to GPU buffers through one persistently mapped staging buffer: the
// CPU copies a block's bytes into the mapping and the GPU copies them on to
// their place, so an upload neither allocates in the driver nor waits for the
// GPU to finish drawing what it replaces (glBufferSubData may do either).
//
// The ring is cut into four quarters. Leaving a quarter fences the copies
// queued from it; entering one waits for its fence, which the GPU has almost
// always passed, since a quarter is reused only after three others were
// filled. A piece larger than a quarter travels in quarter-sized parts.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "render/gl_objects.h"

namespace octocosm {

class UploadRing {
 public:
  // Bytes of staging (rounded up to a multiple of four quarters of 256 bytes).
  explicit UploadRing(std::size_t bytes);
  UploadRing(const UploadRing&) = delete;
  UploadRing& operator=(const UploadRing&) = delete;
  ~UploadRing();

  // Queues a copy of `data` into `target` at byte `offset`; `data` may be
  // reused when this returns. Later GL commands see the bytes.
  void Upload(std::span<const std::uint8_t> data, GLuint target, std::size_t offset);

  std::size_t bytes() const { return 4 * quarter_; }

 private:
  // Moves to the next quarter, fencing the one left and waiting for the one entered.
  void NextQuarter();

  GlBuffer buffer_;
  std::uint8_t* mapped_ = nullptr;
  std::size_t quarter_ = 0;
  std::size_t current_ = 0;  // quarter being filled
  std::size_t used_ = 0;     // bytes of it
  std::array<GLsync, 4> fences_{};
};

}  // namespace octocosm
