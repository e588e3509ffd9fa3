// A set of particle IDs on the GPU, for highlighting: an open-addressing hash
// table (linear probing, load factor at most 1/2, so a look-up takes about
// 1.5 probes whether or not the ID is in the set) that the vertex shader
// probes for every point it draws when a selection is active
// (shaders/splat_vert.glsl, IsSelected). Holds up to kMaxSelectedIds IDs.
// The ID 2^64 - 1 marks an empty slot and cannot be selected.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "render/gl_objects.h"

namespace octocosm {

inline constexpr std::size_t kMaxSelectedIds = std::size_t{1} << 24;

class SelectionSet {
 public:
  // Builds the table on the CPU (duplicates are fine). Throws
  // Error::InvalidArgument for more than kMaxSelectedIds IDs or the ID
  // 2^64 - 1. Needs no GL context; Upload() does.
  explicit SelectionSet(std::span<const std::uint64_t> ids);

  std::size_t size() const { return count_; }
  // The same probe sequence as the shader.
  bool Contains(std::uint64_t id) const;
  // The table as the shader reads it (binding 1): mask, count, 2 words of
  // padding, then (low, high) word pairs.
  const std::vector<std::uint32_t>& words() const { return words_; }

  // Creates or replaces the GPU copy; needs a current GL context.
  void Upload();
  GLuint buffer() const { return buffer_.get(); }

 private:
  std::uint32_t Slot(std::uint64_t id) const;

  std::vector<std::uint32_t> words_;
  std::uint32_t mask_ = 0;
  std::size_t count_ = 0;
  GlBuffer buffer_;
};

// The hash of shaders/splat_vert.glsl: lowbias32 over the two halves.
std::uint32_t SelectionHash(std::uint64_t id);

}  // namespace octocosm
