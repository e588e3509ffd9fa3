// The (ID, leaf) pairs of an epoch whose particle IDs are unique and lie in a
// compact range, gathered without a sort: each leaf stores its ordinal at
// slot `id - first` of one array, which, cut into pages, is the ID index
// (IdIndexEpochWriter::AddTable). Simulation codes number particles 0..N-1 or 1..N (per type,
// in ranges that follow each other), so this is the usual case; otherwise
// ingest sorts the pairs (ingest/external_sorter.h).
//
// IdCensus watches the IDs while the epoch is read and says whether the table
// can be used: every ID seen once, all within `max_span` consecutive values.
// It keeps one bit per value of the range so far (an eighth of a byte per
// slot), growing it as IDs arrive in either direction.
#pragma once

#include <cstdint>
#include <cstdlib>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "base/mutex.h"
#include "index/morton.h"

namespace octocosm {

class IdCensus {
 public:
  // Gives up (dense() false) once the IDs span more than `max_span` values.
  explicit IdCensus(std::uint64_t max_span) : max_span_(max_span) {}

  void Add(std::span<const std::uint64_t> ids);

  // Whether the IDs added so far are unique and span at most max_span values.
  bool dense() const { return dense_; }
  // Meaningful while dense() and count() > 0: the smallest ID and the range
  // from it to the largest ID, both ends included.
  std::uint64_t first() const { return min_; }
  std::uint64_t span() const { return count_ == 0 ? 0 : max_ - min_ + 1; }
  std::uint64_t count() const { return count_; }
  // An ID seen twice, when that is what made dense() false; IDs repeated
  // after the census gave up for the span are not seen.
  std::optional<std::uint64_t> repeated_id() const { return repeated_id_; }

 private:
  void GiveUp();
  // Makes bit `id - base_` exist; false when the IDs would span more than
  // max_span_ values.
  bool Cover(std::uint64_t id);
  // Cover's growth, false where the bitmap would outgrow max_span_.
  bool Grow(std::uint64_t id);

  std::uint64_t max_span_;
  bool dense_ = true;
  std::uint64_t count_ = 0;
  std::uint64_t min_ = 0, max_ = 0;
  std::optional<std::uint64_t> repeated_id_;
  std::uint64_t base_ = 0;  // the ID of bit 0 of words_[0]; a multiple of 64
  std::vector<std::uint64_t> words_;
};

// Slot i holds which leaf has ID first + i: 0 where no particle has that ID,
// else one more than the leaf's ordinal in the order leaves were added (in
// key order after SortLeaves).
// Slots are 16 bits while at most 65535 leaves have been added (10^8
// clustered points make about 34,000) and are widened to 32 bits in place
// when the 65536th arrives: the key itself would take 8 bytes, and the
// table is fresh memory, much of an ingest's cost (docs/INGEST.md).
class DenseIdTable {
 public:
  // The most leaves 16-bit slots number.
  static constexpr std::uint64_t kMostNarrowLeaves = 0xFFFF;

  // Allocates span slots, zero (the kernel's zero pages: untouched slots
  // cost no memory until a leaf writes them), with room to widen them.
  DenseIdTable(std::uint64_t first, std::uint64_t span);

  // Records that `leaf` holds the particles `ids`, and returns the first of
  // them that was recorded already (its slot keeps the leaf it had): two
  // particles with one ID, which the caller refuses naming its input. Calls
  // one after another find every repeat; several threads may call it at
  // once only for IDs that are unique (as IdCensus found them), since two
  // threads writing one slot could both miss the other. An ID outside the
  // range throws InvalidArgument, and so do more than 2^32 - 2 leaves.
  [[nodiscard]] std::optional<std::uint64_t> Add(std::span<const std::uint64_t> ids, NodeKey leaf) EXCLUDES(mutex_);

  // What IdIndexEpochWriter::AddTable writes, once no Add runs: slot i is 0
  // where no leaf recorded ID first() + i, else 1 + the leaf's index in
  // leaves() (the order in which leaves were added). The slots are
  // narrow_slots() while narrow(), else wide_slots(); the other is empty.
  // Unlocked: no thread adds any more.
  bool narrow() const NO_THREAD_SAFETY_ANALYSIS { return narrow_; }
  std::span<const std::uint16_t> narrow_slots() const NO_THREAD_SAFETY_ANALYSIS;
  std::span<const std::uint32_t> wide_slots() const NO_THREAD_SAFETY_ANALYSIS;
  std::span<const std::uint64_t> leaves() const NO_THREAD_SAFETY_ANALYSIS { return leaves_; }

  // Renumbers the leaves in key order, rewriting the slots to match, so that
  // the table (and the ID index written from it) does not depend on the
  // order in which build threads finished their leaves, nor on how the
  // epoch was spread over threads or processes. Once no Add runs; slots no
  // leaf wrote are left untouched (they cost no memory).
  void SortLeaves(int threads) NO_THREAD_SAFETY_ANALYSIS;

  std::uint64_t first() const { return first_; }
  std::uint64_t span() const { return span_; }

 private:
  struct Free {
    void operator()(void* p) const { std::free(p); }
  };
  // Rewrites the 16-bit slots as 32-bit ones, last first (each wide slot
  // covers narrow ones at or after its own index).
  void Widen() REQUIRES(mutex_);

  std::uint64_t first_;
  std::uint64_t span_;
  std::unique_ptr<void, Free> slots_;  // room for span 32-bit slots; the first half holds 16-bit ones while narrow_
  bool narrow_ GUARDED_BY(mutex_) = true;
  // Exclusive: adding a leaf, widening. Shared: writing a leaf's slots, which
  // for distinct IDs touch distinct slots.
  SharedMutex mutex_;
  std::vector<std::uint64_t> leaves_ GUARDED_BY(mutex_);  // leaf keys by ordinal
};

}  // namespace octocosm
