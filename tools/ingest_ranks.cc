#include "tools/ingest_ranks.h"

#include <cstdio>
#include <algorithm>
#include <climits>
#include <span>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "base/error.h"
#include "base/parallel_for.h"
#include "base/progress.h"
#include "ingest/rank_group.h"

#if OCTOCOSM_WITH_MPI
#include <mpi.h>
#endif

namespace octocosm {

int LaunchedProcesses() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE"}) {
    const char* value = std::getenv(name);
    if (value != nullptr && std::atoi(value) > 0) return std::atoi(value);
  }
  return 1;
}

#if OCTOCOSM_WITH_MPI

namespace {

// MPI for the length of one ingest: only the main thread calls it.
class MpiSession {
 public:
  MpiSession() {
    int provided = 0;
    if (MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS) {
      throw Error::Io("MPI", "MPI_Init_thread failed");
    }
  }
  ~MpiSession() { MPI_Finalize(); }
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
};

int CommRank(MPI_Comm comm) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  return rank;
}

int CommSize(MPI_Comm comm) {
  int size = 0;
  MPI_Comm_size(comm, &size);
  return size;
}

// The ranks that share this one's node (and its cores and memory).
int RanksOnThisNode() {
  MPI_Comm node;
  MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, CommRank(MPI_COMM_WORLD), MPI_INFO_NULL, &node);
  const int size = CommSize(node);
  MPI_Comm_free(&node);
  return size;
}

// This rank's error, where a user sees it.
void ReportFailure(int rank, const std::string& message) {
  std::fprintf(stderr, "octocosm: ingest rank %d: %s\n", rank, message.c_str());
  std::fflush(stderr);
}

[[noreturn]] void EndJob() {
  MPI_Abort(MPI_COMM_WORLD, 1);
  std::abort();  // MPI_Abort does not return
}

// Ends the whole job: this rank's error first.
[[noreturn]] void AbortWith(int rank, const std::string& message) {
  ReportFailure(rank, message);
  EndJob();
}

// Every rank's text on rank 0, in rank order.
std::vector<std::string> GatherText(const std::string& text, int ranks) {
  const int length = static_cast<int>(text.size());
  std::vector<int> lengths(static_cast<std::size_t>(ranks)), offsets(static_cast<std::size_t>(ranks));
  MPI_Gather(&length, 1, MPI_INT, lengths.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
  std::string all;
  if (CommRank(MPI_COMM_WORLD) == 0) {
    long long total = 0;
    for (int r = 0; r < ranks; ++r) {
      offsets[static_cast<std::size_t>(r)] = static_cast<int>(total);
      total += lengths[static_cast<std::size_t>(r)];
    }
    all.resize(static_cast<std::size_t>(total));
  }
  MPI_Gatherv(text.data(), length, MPI_CHAR, all.data(), lengths.data(), offsets.data(), MPI_CHAR, 0, MPI_COMM_WORLD);
  std::vector<std::string> texts;
  if (CommRank(MPI_COMM_WORLD) != 0) return texts;
  for (int r = 0; r < ranks; ++r) {
    texts.push_back(all.substr(static_cast<std::size_t>(offsets[static_cast<std::size_t>(r)]),
                               static_cast<std::size_t>(lengths[static_cast<std::size_t>(r)])));
  }
  return texts;
}

// The ranks of MPI_COMM_WORLD as an epoch spread over them sees them.
class WorldGroup final : public RankGroup {
 public:
  int rank() const override { return CommRank(MPI_COMM_WORLD); }
  int size() const override { return CommSize(MPI_COMM_WORLD); }
  void Sum(std::span<std::uint64_t> values) override { Reduce(values, MPI_SUM); }
  void Max(std::span<std::uint64_t> values) override { Reduce(values, MPI_MAX); }

  std::vector<Bytes> Exchange(const std::vector<Bytes>& outgoing) override {
    const std::size_t ranks = static_cast<std::size_t>(size());
    std::vector<long long> send_sizes(ranks), receive_sizes(ranks);
    for (std::size_t q = 0; q < ranks; ++q) send_sizes[q] = static_cast<long long>(outgoing[q].size());
    MPI_Alltoall(send_sizes.data(), 1, MPI_LONG_LONG, receive_sizes.data(), 1, MPI_LONG_LONG, MPI_COMM_WORLD);
    // MPI_Alltoallv counts in int: a round's batch stays far below 2 GiB.
    std::vector<int> send_counts(ranks), send_offsets(ranks), receive_counts(ranks), receive_offsets(ranks);
    Bytes send;
    std::size_t received = 0;
    for (std::size_t q = 0; q < ranks; ++q) {
      if (send_sizes[q] > INT_MAX || receive_sizes[q] > INT_MAX || send.size() > INT_MAX || received > INT_MAX) {
        throw Error::InvalidArgument("ingest: a round of the exchange between ranks exceeds 2 GiB; read smaller batches");
      }
      send_offsets[q] = static_cast<int>(send.size());
      send_counts[q] = static_cast<int>(send_sizes[q]);
      send.insert(send.end(), outgoing[q].begin(), outgoing[q].end());
      receive_offsets[q] = static_cast<int>(received);
      receive_counts[q] = static_cast<int>(receive_sizes[q]);
      received += static_cast<std::size_t>(receive_sizes[q]);
    }
    Bytes all(received);
    MPI_Alltoallv(send.data(), send_counts.data(), send_offsets.data(), MPI_BYTE, all.data(), receive_counts.data(),
                  receive_offsets.data(), MPI_BYTE, MPI_COMM_WORLD);
    std::vector<Bytes> incoming(ranks);
    for (std::size_t q = 0; q < ranks; ++q) {
      const auto* begin = all.data() + receive_offsets[q];
      incoming[q].assign(begin, begin + receive_counts[q]);
    }
    return incoming;
  }

  void Send(int to, const Bytes& message) override {
    const unsigned long long length = message.size();
    MPI_Send(&length, 1, MPI_UNSIGNED_LONG_LONG, to, kLengthTag, MPI_COMM_WORLD);
    for (std::size_t done = 0; done < message.size();) {
      const int piece = static_cast<int>(std::min<std::size_t>(message.size() - done, kMostPiece));
      MPI_Send(message.data() + done, piece, MPI_BYTE, to, kPieceTag, MPI_COMM_WORLD);
      done += static_cast<std::size_t>(piece);
    }
  }

  Bytes Receive(int from) override {
    unsigned long long length = 0;
    MPI_Recv(&length, 1, MPI_UNSIGNED_LONG_LONG, from, kLengthTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    Bytes message(static_cast<std::size_t>(length));
    for (std::size_t done = 0; done < message.size();) {
      const int piece = static_cast<int>(std::min<std::size_t>(message.size() - done, kMostPiece));
      MPI_Recv(message.data() + done, piece, MPI_BYTE, from, kPieceTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      done += static_cast<std::size_t>(piece);
    }
    return message;
  }

 private:
  static constexpr int kLengthTag = 1, kPieceTag = 2;
  static constexpr std::size_t kMostPiece = std::size_t{1} << 30;

  static void Reduce(std::span<std::uint64_t> values, MPI_Op op) {
    MPI_Allreduce(MPI_IN_PLACE, values.data(), static_cast<int>(values.size()), MPI_UINT64_T, op, MPI_COMM_WORLD);
  }
};

}  // namespace

std::optional<IngestReport> IngestOnRanks(IngestOptions options) {
  MpiSession mpi;
  const int rank = CommRank(MPI_COMM_WORLD);
  const int ranks = CommSize(MPI_COMM_WORLD);
  const int on_node = RanksOnThisNode();
  if (options.threads == 0) {
    const unsigned share = std::max(1u, std::thread::hardware_concurrency() / static_cast<unsigned>(on_node));
    const unsigned allowed = CoresAllowed();
    options.threads = std::min(share, allowed);
    if (allowed < share && rank == 0) {
      std::fprintf(stderr,
                   "octocosm: ingest rank 0: mpirun bound this rank to %u of the %u cores that are its share of the "
                   "node; mpirun --bind-to none (or --map-by slot:PE=%u) lets it use them all\n",
                   allowed, share, share);
    }
  }
  if (options.memory_budget == 0) {
    options.memory_budget = std::max<std::uint64_t>(DefaultMemoryBudget() / static_cast<std::uint64_t>(on_node),
                                                    std::uint64_t{256} << 20);
  }
  // One progress display: rank 0's.
  if (rank != 0) options.quiet = true;
  // A single epoch is spread over the ranks; a series' epochs are shared out.
  const bool spread = options.inputs.size() == 1 && ranks > 1;
  if (rank == 0 && !spread && static_cast<std::size_t>(ranks) > options.inputs.size()) {
    std::fprintf(stderr,
                 "octocosm: ingest: %d ranks for %zu epochs: the epochs of a series are shared out, not spread, so %zu "
                 "rank(s) have none\n",
                 ranks, options.inputs.size(), static_cast<std::size_t>(ranks) - options.inputs.size());
  }

  // Rank 0 takes the output (as a single ingest would) and fixes the ids
  // every part's page files carry.
  std::unique_ptr<IngestAssembly> assembly;
  std::uint64_t ids[2] = {0, 0};
  if (rank == 0) {
    try {
      assembly = std::make_unique<IngestAssembly>(options, static_cast<std::size_t>(ranks));
      ids[0] = assembly->store_id();
      ids[1] = assembly->id_store_id();
    } catch (const std::exception& e) {
      AbortWith(rank, e.what());
    }
  }
  MPI_Bcast(ids, 2, MPI_UINT64_T, 0, MPI_COMM_WORLD);

  IngestShare share = IngestAssembly::Share(options.inputs.size(), static_cast<std::size_t>(rank),
                                            static_cast<std::size_t>(ranks));
  if (spread) {
    share.first_epoch = 0;
    share.end_epoch = 1;
  }
  share.store_id = ids[0];
  share.id_store_id = ids[1];
  std::string part_json;
  try {
    const std::string part_directory = IngestAssembly::PartDirectory(options.output, static_cast<std::size_t>(rank));
    WorldGroup world;
    const IngestPart part = spread ? IngestSpreadInto(options, share, world, part_directory)
                                   : IngestShareInto(options, share, part_directory);
    part_json = part.ToJson().dump();
  } catch (const std::exception& e) {
    // MPI_Abort runs no destructors: rank 0 removes the output, and the
    // parts other ranks may have finished in it, before it ends the job;
    // its error goes out first, for a rank still writing there fails next.
    ReportFailure(rank, e.what());
    assembly.reset();
    EndJob();
  }

  const std::vector<std::string> texts = GatherText(part_json, ranks);
  if (rank != 0) return std::nullopt;
  std::vector<IngestPart> parts;
  // A spread epoch is all in rank 0's part; the others' are removed with it.
  for (int r = 0; r < (spread ? 1 : ranks); ++r) {
    parts.push_back(IngestPart::FromJson(nlohmann::json::parse(texts[static_cast<std::size_t>(r)]),
                                         "rank " + std::to_string(r) + "'s part"));
  }
  return assembly->Assemble(parts);
}

#else

std::optional<IngestReport> IngestOnRanks(IngestOptions) {
  throw Error::InvalidArgument("ingest: this octocosm was built without MPI, so it cannot share an ingest among the " +
                               std::to_string(LaunchedProcesses()) +
                               " processes mpirun started; install libopenmpi-dev (Debian) and build again");
}

#endif

}  // namespace octocosm
