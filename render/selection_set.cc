#include "render/selection_set.h"

#include <algorithm>
#include <bit>
#include <string>

#include "base/error.h"

namespace octocosm {
namespace {

constexpr std::uint64_t kEmpty = ~std::uint64_t{0};
constexpr std::size_t kHeaderWords = 4;

std::uint32_t Mix32(std::uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}

}  // namespace

std::uint32_t SelectionHash(std::uint64_t id) {
  return Mix32(static_cast<std::uint32_t>(id) ^ Mix32(static_cast<std::uint32_t>(id >> 32)));
}

SelectionSet::SelectionSet(std::span<const std::uint64_t> ids) {
  if (ids.size() > kMaxSelectedIds) {
    throw Error::InvalidArgument("a selection holds at most " + std::to_string(kMaxSelectedIds) + " IDs, not " +
                                 std::to_string(ids.size()));
  }
  const std::size_t slots = std::max<std::size_t>(16, std::bit_ceil(2 * ids.size()));
  mask_ = static_cast<std::uint32_t>(slots - 1);
  words_.assign(kHeaderWords + 2 * slots, 0xFFFFFFFFu);
  for (const std::uint64_t id : ids) {
    if (id == kEmpty) throw Error::InvalidArgument("particle ID 18446744073709551615 (2^64 - 1) cannot be selected");
    std::uint32_t slot = Slot(id);
    for (;;) {
      std::uint32_t* s = &words_[kHeaderWords + 2 * static_cast<std::size_t>(slot)];
      const std::uint64_t held = s[0] | (std::uint64_t{s[1]} << 32);
      if (held == id) break;
      if (held == kEmpty) {
        s[0] = static_cast<std::uint32_t>(id);
        s[1] = static_cast<std::uint32_t>(id >> 32);
        ++count_;
        break;
      }
      slot = (slot + 1) & mask_;
    }
  }
  words_[0] = mask_;
  words_[1] = static_cast<std::uint32_t>(count_);
  words_[2] = words_[3] = 0;
}

std::uint32_t SelectionSet::Slot(std::uint64_t id) const { return SelectionHash(id) & mask_; }

bool SelectionSet::Contains(std::uint64_t id) const {
  if (id == kEmpty) return false;
  std::uint32_t slot = Slot(id);
  for (std::uint32_t probe = 0; probe <= mask_; ++probe) {
    const std::uint32_t* s = &words_[kHeaderWords + 2 * static_cast<std::size_t>(slot)];
    const std::uint64_t held = s[0] | (std::uint64_t{s[1]} << 32);
    if (held == id) return true;
    if (held == kEmpty) return false;
    slot = (slot + 1) & mask_;
  }
  return false;
}

void SelectionSet::Upload() {
  buffer_ = MakeGlBuffer(words_.size() * sizeof(std::uint32_t), words_.data(), 0);
}

}  // namespace octocosm
