#include "tools/ingest_ranks.h"

#include <cstdio>
#include <algorithm>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "base/error.h"
#include "base/parallel_for.h"
#include "base/progress.h"

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

// Ends the whole job: this rank's error first, where a user sees it.
[[noreturn]] void AbortWith(int rank, const std::string& message) {
  std::fprintf(stderr, "octocosm: ingest rank %d: %s\n", rank, message.c_str());
  std::fflush(stderr);
  MPI_Abort(MPI_COMM_WORLD, 1);
  std::abort();  // MPI_Abort does not return
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
  if (rank == 0 && static_cast<std::size_t>(ranks) > options.inputs.size()) {
    std::fprintf(stderr,
                 "octocosm: ingest: %d ranks for %zu epoch(s): an epoch is one rank's work, so %zu rank(s) have none\n",
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
  share.store_id = ids[0];
  share.id_store_id = ids[1];
  std::string part_json;
  try {
    const IngestPart part = IngestShareInto(options, share, IngestAssembly::PartDirectory(options.output,
                                                                                           static_cast<std::size_t>(rank)));
    part_json = part.ToJson().dump();
  } catch (const std::exception& e) {
    AbortWith(rank, e.what());
  }

  const std::vector<std::string> texts = GatherText(part_json, ranks);
  if (rank != 0) return std::nullopt;
  std::vector<IngestPart> parts;
  for (int r = 0; r < ranks; ++r) {
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
