// The processes (ranks) that ingest one epoch together, as the ingest sees
// them: a handful of collective operations, so that ingest/ needs no MPI
// headers. tools/ingest_ranks.cc implements them over MPI_COMM_WORLD. Every
// call is collective but Send and Receive, and only the thread that made
// the group calls it.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "storage/block_source.h"

namespace octocosm {

class RankGroup {
 public:
  virtual ~RankGroup() = default;
  virtual int rank() const = 0;
  virtual int size() const = 0;
  // Every rank's values summed, element by element, on every rank.
  virtual void Sum(std::span<std::uint64_t> values) = 0;
  // The largest of every rank's values, element by element, on every rank.
  virtual void Max(std::span<std::uint64_t> values) = 0;
  // outgoing[q] goes to rank q (one entry per rank); returns what each rank
  // sent this one, by sender.
  virtual std::vector<Bytes> Exchange(const std::vector<Bytes>& outgoing) = 0;
  // One message to, or from, one rank; in order between any two ranks.
  virtual void Send(int to, const Bytes& message) = 0;
  virtual Bytes Receive(int from) = 0;
};

}  // namespace octocosm
