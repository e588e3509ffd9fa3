// `mpirun -n P octocosm ingest ...`: one ingest spread over P processes
// (ranks). The epochs of the series are shared out in consecutive runs
// (IngestAssembly::Share); each rank ingests its share into a part inside
// the output, rank 0 adopts the parts' page files and writes the manifests.
// A single snapshot is spread over the ranks instead (IngestSpreadInto,
// through a RankGroup over MPI_COMM_WORLD). Either way the store is the one
// a single process writes (ingest/ingest.h). The output
// must be on a file system every rank sees at the same path.
//
// A rank that fails prints its error and ends the whole job (MPI_Abort);
// the others are stopped by mpirun's SIGTERM, which removes each one's part
// and rank 0's output (base/interrupt_cleanup.h).
#pragma once

#include <optional>

#include "ingest/ingest.h"

namespace octocosm {

// How many processes the launcher started this one among: 1 when not run by
// mpirun (Open MPI's, or a PMI launcher such as srun).
int LaunchedProcesses();

// Runs the ingest on the ranks of MPI_COMM_WORLD. Where the options leave
// them to the default, each rank takes its share of its node's cores and
// memory. Returns the report on rank 0, nothing on the others. Throws on the
// rank whose error ends the ingest.
std::optional<IngestReport> IngestOnRanks(IngestOptions options);

}  // namespace octocosm
