#include "ingest/dense_id_table.h"

#include <algorithm>
#include <cstring>
#include <new>
#include <numeric>
#include <string>
#include <type_traits>

#include "base/error.h"
#include "base/parallel_for.h"

namespace octocosm {

void IdCensus::Add(std::span<const std::uint64_t> ids) {
  if (!dense_) return;
  for (const std::uint64_t id : ids) {
    if (count_ == 0) {
      min_ = max_ = id;
      base_ = id & ~std::uint64_t{63};
      words_.assign(1, 0);
    }
    std::uint64_t bit = id - base_;  // wraps to a huge value below base_
    if (bit >= 64 * words_.size()) {
      if (!Cover(id)) return GiveUp();
      bit = id - base_;
    }
    std::uint64_t& word = words_[bit >> 6];
    const std::uint64_t mask = std::uint64_t{1} << (bit & 63);
    if ((word & mask) != 0) {  // a duplicate
      repeated_id_ = id;
      return GiveUp();
    }
    word |= mask;
    min_ = std::min(min_, id);
    max_ = std::max(max_, id);
    ++count_;
  }
  if (span() > max_span_) GiveUp();
}

bool IdCensus::Cover(std::uint64_t id) {
  if (std::max(max_, id) - std::min(min_, id) >= max_span_) return false;
  if (Grow(id)) return true;
  // Room made earlier below the smallest ID is in the way: drop it.
  words_.resize(static_cast<std::size_t>((max_ - base_) / 64 + 1));
  const std::uint64_t unused_below = (min_ - base_) / 64;
  words_.erase(words_.begin(), words_.begin() + static_cast<std::ptrdiff_t>(unused_below));
  base_ += 64 * unused_below;
  return Grow(id);
}

bool IdCensus::Grow(std::uint64_t id) {
  // Whole words at most max_span_ bits apart can be needed, plus one at each end.
  const std::uint64_t max_words = max_span_ / 64 + 2;
  if (id < base_) {
    const std::uint64_t needed = (base_ - (id & ~std::uint64_t{63})) / 64;
    if (words_.size() + needed > max_words) return false;
    // Room for as many again as the bitmap holds, so that IDs arriving in
    // decreasing order grow it geometrically, not one copy per word.
    const std::uint64_t added =
        std::max(needed, std::min<std::uint64_t>({words_.size(), base_ / 64, max_words - words_.size()}));
    words_.insert(words_.begin(), static_cast<std::size_t>(added), 0);
    base_ -= 64 * added;
  } else {
    const std::uint64_t words = (id - base_) / 64 + 1;
    if (words > max_words) return false;
    words_.resize(static_cast<std::size_t>(words));  // capacity grows geometrically
  }
  return true;
}

void IdCensus::GiveUp() {
  dense_ = false;
  std::vector<std::uint64_t>().swap(words_);
}

DenseIdTable::DenseIdTable(std::uint64_t first, std::uint64_t span) : first_(first), span_(span) {
  if (span > SIZE_MAX / sizeof(std::uint32_t)) throw std::bad_alloc();
  // calloc, not a value-initialized array: fresh memory from the kernel is
  // zero already, and writing the zeros would fault in every page on this
  // thread instead of where the leaves write.
  slots_.reset(std::calloc(std::max<std::uint64_t>(span, 1), sizeof(std::uint32_t)));
  if (!slots_) throw std::bad_alloc();
}

std::span<const std::uint16_t> DenseIdTable::narrow_slots() const {
  if (!narrow_) return {};
  return {static_cast<const std::uint16_t*>(slots_.get()), static_cast<std::size_t>(span_)};
}

std::span<const std::uint32_t> DenseIdTable::wide_slots() const {
  if (narrow_) return {};
  return {static_cast<const std::uint32_t*>(slots_.get()), static_cast<std::size_t>(span_)};
}

void DenseIdTable::Widen() {
  // Through memcpy: the same bytes are read as 16-bit and written as 32-bit
  // values. Slot i's wide bytes [4i, 4i + 4) hold narrow slots 2i and 2i + 1,
  // both read already when going down from the last.
  auto* bytes = static_cast<std::uint8_t*>(slots_.get());
  for (std::uint64_t i = span_; i-- > 0;) {
    std::uint16_t narrow;
    std::memcpy(&narrow, bytes + 2 * i, sizeof(narrow));
    const std::uint32_t wide = narrow;
    std::memcpy(bytes + 4 * i, &wide, sizeof(wide));
  }
  narrow_ = false;
}

namespace {

template <typename Slot>
std::optional<std::uint64_t> RecordLeaf(Slot* slots, std::uint64_t first, std::uint64_t span,
                                        std::span<const std::uint64_t> ids, Slot slot_value) {
  // A leaf's IDs lie scattered over the table, so each slot is a cache miss;
  // asking for the slots this many IDs ahead lets the misses overlap.
  constexpr std::size_t kAhead = 16;
  std::optional<std::uint64_t> repeated;
  for (std::size_t k = 0; k < ids.size(); ++k) {
    if (k + kAhead < ids.size()) {
      const std::uint64_t ahead = ids[k + kAhead] - first;
      if (ahead < span) __builtin_prefetch(slots + ahead, 1);
    }
    const std::uint64_t id = ids[k];
    const std::uint64_t slot = id - first;
    if (slot >= span) {
      throw Error::InvalidArgument("DenseIdTable: ID " + std::to_string(id) + " lies outside the table's " +
                                   std::to_string(first) + " .. " + std::to_string(first + span - 1));
    }
    if (slots[slot] != 0) {
      if (!repeated) repeated = id;
      continue;
    }
    slots[slot] = slot_value;
  }
  return repeated;
}

}  // namespace

std::optional<std::uint64_t> DenseIdTable::Add(std::span<const std::uint64_t> ids, NodeKey leaf) {
  std::uint32_t slot_value = 0;
  {
    WriterLock lock(mutex_);
    if (leaves_.size() >= UINT32_MAX - 1) {
      throw Error::InvalidArgument("DenseIdTable: more than " + std::to_string(UINT32_MAX - 1) + " leaves");
    }
    leaves_.push_back(leaf.value());
    slot_value = static_cast<std::uint32_t>(leaves_.size());
    if (narrow_ && slot_value > kMostNarrowLeaves) Widen();
  }
  ReaderLock lock(mutex_);
  if (narrow_) {
    return RecordLeaf(static_cast<std::uint16_t*>(slots_.get()), first_, span_, ids,
                      static_cast<std::uint16_t>(slot_value));
  }
  return RecordLeaf(static_cast<std::uint32_t*>(slots_.get()), first_, span_, ids, slot_value);
}

void DenseIdTable::SortLeaves(int threads) {
  const std::span<const std::uint64_t> keys_by_ordinal = leaves();  // unlocked, as leaves() is
  std::vector<std::uint32_t> order(keys_by_ordinal.size());
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(),
            [&](std::uint32_t a, std::uint32_t b) { return keys_by_ordinal[a] < keys_by_ordinal[b]; });
  // renumber[old ordinal + 1] = new ordinal + 1; 0 stays 0.
  std::vector<std::uint32_t> renumber(leaves_.size() + 1, 0);
  bool sorted = true;
  for (std::size_t k = 0; k < order.size(); ++k) {
    renumber[order[k] + 1] = static_cast<std::uint32_t>(k + 1);
    sorted &= order[k] == k;
  }
  if (sorted) return;
  const auto rewrite = [&](auto* slots) {
    ParallelFor(static_cast<std::size_t>(span_), threads, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        if (slots[i] != 0) slots[i] = static_cast<std::remove_pointer_t<decltype(slots)>>(renumber[slots[i]]);
      }
    });
  };
  if (narrow_) {
    rewrite(static_cast<std::uint16_t*>(slots_.get()));
  } else {
    rewrite(static_cast<std::uint32_t*>(slots_.get()));
  }
  std::vector<std::uint64_t> keys(leaves_.size());
  for (std::size_t k = 0; k < order.size(); ++k) keys[k] = leaves_[order[k]];
  leaves_ = std::move(keys);
}

}  // namespace octocosm
