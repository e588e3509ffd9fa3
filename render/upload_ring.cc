#include "render/upload_ring.h"

#include <algorithm>
#include <cstring>

#include "base/error.h"

namespace octocosm {

UploadRing::UploadRing(std::size_t bytes) {
  quarter_ = std::max<std::size_t>(256, (bytes / 4 + 255) / 256 * 256);
  constexpr GLbitfield kMapped = GL_MAP_WRITE_BIT | GL_MAP_PERSISTENT_BIT | GL_MAP_COHERENT_BIT;
  buffer_ = MakeGlBuffer(4 * quarter_, nullptr, kMapped);
  mapped_ = static_cast<std::uint8_t*>(
      glMapNamedBufferRange(buffer_.get(), 0, static_cast<GLsizeiptr>(4 * quarter_), kMapped));
  if (mapped_ == nullptr) throw Error::NotSupported("OpenGL", "cannot map the upload staging buffer");
  CheckGlError("allocating the upload staging buffer");
}

UploadRing::~UploadRing() {
  for (GLsync fence : fences_) {
    if (fence != nullptr) glDeleteSync(fence);
  }
  if (mapped_ != nullptr) glUnmapNamedBuffer(buffer_.get());
}

void UploadRing::NextQuarter() {
  fences_[current_] = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
  current_ = (current_ + 1) % fences_.size();
  used_ = 0;
  GLsync& fence = fences_[current_];
  if (fence == nullptr) return;
  GLenum status = glClientWaitSync(fence, GL_SYNC_FLUSH_COMMANDS_BIT, 1'000'000'000);
  while (status == GL_TIMEOUT_EXPIRED) status = glClientWaitSync(fence, GL_SYNC_FLUSH_COMMANDS_BIT, 1'000'000'000);
  if (status == GL_WAIT_FAILED) throw Error::NotSupported("OpenGL", "waiting for an upload's staging failed");
  glDeleteSync(fence);
  fence = nullptr;
}

void UploadRing::Upload(std::span<const std::uint8_t> data, GLuint target, std::size_t offset) {
  while (!data.empty()) {
    if (used_ == quarter_) NextQuarter();
    const std::size_t piece = std::min(data.size(), quarter_ - used_);
    const std::size_t at = current_ * quarter_ + used_;
    std::memcpy(mapped_ + at, data.data(), piece);
    glCopyNamedBufferSubData(buffer_.get(), target, static_cast<GLintptr>(at), static_cast<GLintptr>(offset),
                             static_cast<GLsizeiptr>(piece));
    // Keep the next piece 4-byte aligned in the ring (copies of any alignment
    // are valid; aligned ones are the fast case on every driver).
    used_ = std::min(quarter_, (used_ + piece + 3) / 4 * 4);
    data = data.subspan(piece);
    offset += piece;
  }
}

}  // namespace octocosm
