// Ranks that are threads of one process (a RankGroup without MPI), for
// tests of what the ranks of a spread ingest do together.
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <exception>
#include <functional>
#include <mutex>
#include <span>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "ingest/rank_group.h"

namespace octocosm::testing_support {

// What the threads that play ranks share. A rank that fails breaks the
// group: the others then fail at their next collective step instead of
// waiting for it.
struct RankHub {
  explicit RankHub(int ranks)
      : size(ranks), mail(static_cast<std::size_t>(ranks)), values(static_cast<std::size_t>(ranks)),
        queues(static_cast<std::size_t>(ranks * ranks)) {}

  // Every rank arrives before any goes on.
  void Barrier() {
    std::unique_lock lock(mutex);
    if (broken) throw std::runtime_error("another rank failed");
    const std::uint64_t generation_now = generation;
    if (++arrived == size) {
      arrived = 0;
      ++generation;
      changed.notify_all();
      return;
    }
    changed.wait(lock, [&] { return generation != generation_now || broken; });
    if (broken) throw std::runtime_error("another rank failed");
  }
  void Break() {
    std::lock_guard lock(mutex);
    broken = true;
    changed.notify_all();
  }

  const int size;
  std::mutex mutex;
  std::condition_variable changed;
  int arrived = 0;
  std::uint64_t generation = 0;
  bool broken = false;
  std::vector<std::vector<Bytes>> mail;             // Exchange: [from][to]
  std::vector<Bytes> values;                        // Sum and Max
  std::vector<std::deque<Bytes>> queues;            // Send: [from * size + to]
};

class ThreadRankGroup : public RankGroup {
 public:
  ThreadRankGroup(RankHub& hub, int rank) : hub_(hub), rank_(rank) {}
  int rank() const override { return rank_; }
  int size() const override { return hub_.size; }
  void Sum(std::span<std::uint64_t> values) override {
    Reduce(values, [](std::uint64_t a, std::uint64_t b) { return a + b; });
  }
  void Max(std::span<std::uint64_t> values) override {
    Reduce(values, [](std::uint64_t a, std::uint64_t b) { return std::max(a, b); });
  }
  std::vector<Bytes> Exchange(const std::vector<Bytes>& outgoing) override {
    hub_.mail[static_cast<std::size_t>(rank_)] = outgoing;
    hub_.Barrier();
    std::vector<Bytes> incoming;
    for (int from = 0; from < hub_.size; ++from) {
      incoming.push_back(hub_.mail[static_cast<std::size_t>(from)][static_cast<std::size_t>(rank_)]);
    }
    hub_.Barrier();
    return incoming;
  }
  void Send(int to, const Bytes& message) override {
    std::lock_guard lock(hub_.mutex);
    hub_.queues[static_cast<std::size_t>(rank_ * hub_.size + to)].push_back(message);
    hub_.changed.notify_all();
  }
  Bytes Receive(int from) override {
    std::unique_lock lock(hub_.mutex);
    std::deque<Bytes>& queue = hub_.queues[static_cast<std::size_t>(from * hub_.size + rank_)];
    hub_.changed.wait(lock, [&] { return !queue.empty() || hub_.broken; });
    if (queue.empty()) throw std::runtime_error("another rank failed");
    Bytes message = std::move(queue.front());
    queue.pop_front();
    return message;
  }

 private:
  // Every rank's values in the hub, as bytes, then each combines them all.
  template <typename T, typename Combine>
  void Reduce(std::span<T> values, Combine combine) {
    const auto* bytes = reinterpret_cast<const std::uint8_t*>(values.data());
    hub_.values[static_cast<std::size_t>(rank_)].assign(bytes, bytes + values.size_bytes());
    hub_.Barrier();
    for (int from = 0; from < hub_.size; ++from) {
      if (from == rank_) continue;
      const T* theirs = reinterpret_cast<const T*>(hub_.values[static_cast<std::size_t>(from)].data());
      for (std::size_t i = 0; i < values.size(); ++i) values[i] = combine(values[i], theirs[i]);
    }
    hub_.Barrier();
  }

  RankHub& hub_;
  const int rank_;
};

// Runs `body` on `ranks` threads, one rank each; rethrows the first failure
// that was not another rank's.
void RunRanks(int ranks, const std::function<void(RankGroup&)>& body) {
  RankHub hub(ranks);
  std::vector<std::exception_ptr> failures(static_cast<std::size_t>(ranks));
  std::vector<std::thread> threads;
  for (int r = 0; r < ranks; ++r) {
    threads.emplace_back([&, r] {
      ThreadRankGroup group(hub, r);
      try {
        body(group);
      } catch (...) {
        failures[static_cast<std::size_t>(r)] = std::current_exception();
        hub.Break();
      }
    });
  }
  for (std::thread& t : threads) t.join();
  std::exception_ptr first_broken;
  for (const std::exception_ptr& failure : failures) {
    if (!failure) continue;
    try {
      std::rethrow_exception(failure);
    } catch (const std::runtime_error& e) {
      if (std::string(e.what()) != "another rank failed") throw;
      first_broken = failure;
    }
  }
  if (first_broken) std::rethrow_exception(first_broken);
}

}  // namespace octocosm::testing_support
