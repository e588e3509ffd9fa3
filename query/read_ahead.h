// ReadAhead: results of a list of reads, handed out in list order, with
// several reads in flight when each waits a round trip to a server.
//
//   ReadAhead<IndexEntry, DecodedBlock> blocks(std::move(entries), remote ? 16 : 1, read);
//   while (std::optional<DecodedBlock> block = blocks.Next()) Use(*block);
//
// With depth 1 each read runs inside Next(), on the caller's thread. With a
// larger depth, Next() keeps up to `depth` reads running on threads of their
// own (std::async) and waits for the oldest. A read that throws throws from
// the Next() that hands out its result; reads already started run to their
// end before the ReadAhead is destroyed. The read function may run on
// several threads at once, and must not refer to anything the owner of the
// ReadAhead moves.
#pragma once

#include <cstddef>
#include <deque>
#include <functional>
#include <future>
#include <optional>
#include <utility>
#include <vector>

namespace octocosm {

// Reads kept in flight against a store on a server: enough to cover a round
// trip of tens of milliseconds at blocks of a few hundred kilobytes.
inline constexpr std::size_t kRemoteReadsInFlight = 16;

template <typename Input, typename Result>
class ReadAhead {
 public:
  using Read = std::function<Result(const Input&)>;

  ReadAhead(std::vector<Input> inputs, std::size_t depth, Read read)
      : inputs_(std::move(inputs)), depth_(depth == 0 ? 1 : depth), read_(std::move(read)) {}
  ReadAhead(ReadAhead&&) = default;
  ReadAhead& operator=(ReadAhead&&) = default;

  // The next input's result, or nullopt after the last.
  std::optional<Result> Next() {
    if (depth_ == 1) {
      if (next_ == inputs_.size()) return std::nullopt;
      return read_(inputs_[next_++]);
    }
    // The reads get the input by value and the function by shared copy:
    // the vector and this object may move while they run.
    while (running_.size() < depth_ && next_ < inputs_.size()) {
      running_.push_back(std::async(std::launch::async, [read = read_, input = inputs_[next_++]] { return read(input); }));
    }
    if (running_.empty()) return std::nullopt;
    std::future<Result> oldest = std::move(running_.front());
    running_.pop_front();
    return oldest.get();
  }

  std::size_t size() const { return inputs_.size(); }

 private:
  std::vector<Input> inputs_;
  std::size_t depth_;
  Read read_;
  std::size_t next_ = 0;
  std::deque<std::future<Result>> running_;
};

}  // namespace octocosm
