// octocosm ingest: snapshots -> store.
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "base/progress.h"
#include "storage/page_file_format.h"
#include "tools/cli_util.h"
#include "tools/commands.h"
#include "tools/ingest_ranks.h"
#include "ingest/ingest.h"
#include "tools/read_flags.h"

namespace octocosm {

void AddIngestCommand(CLI::App& app) {
  struct Flags {
    IngestOptions options;
    ReadFlags read;
    std::string memory, page_size = "4K", cube, clip_box, coarse = "clusters";
  };
  auto flags = std::make_shared<Flags>();
  IngestOptions& o = flags->options;
  CLI::App* cmd = app.add_subcommand(
      "ingest",
      "Build a level-of-detail store from snapshots, out of core. Give one snapshot per epoch, in time order;\n"
      "a multi-file snapshot is named by its base name (snap_005 for snap_005.0, snap_005.1, ...) or any of\n"
      "its files. Formats: GADGET 1 and 2 (either endianness), HDF5 (GADGET-4, AREPO, SWIFT), raw binary\n"
      "(--format raw --raw-layout), CSV (docs/INPUT_FORMATS.md). Runs with glibc's huge-page malloc\n"
      "(GLIBC_TUNABLES=glibc.malloc.hugetlb=1) unless GLIBC_TUNABLES already sets it (docs/INGEST.md).\n"
      "Under mpirun (mpirun -n P octocosm ingest ...) the epochs of a series are shared among the P ranks,\n"
      "and a single snapshot's particles are spread over them by key range; each rank has --memory and\n"
      "--threads of its own (default: its share of its node's); the store is the one a single process\n"
      "writes (docs/INGEST.md, \"Over MPI ranks\").");
  cmd->add_option("inputs", o.inputs, "snapshots, one per epoch")->required();
  cmd->add_option("-o,--output", o.output, "store directory to create (must not hold a store)")->required();
  cmd->add_option("-n,--capacity", o.tree.capacity, "most points per node")->default_val(16000)->check(CLI::Range(1, 100000000));
  cmd->add_option("--max-depth", o.tree.max_level, "depth limit of the tree (0-21); coincident points stop here")
      ->default_val(21)->check(CLI::Range(0, 21));
  cmd->add_option("--alpha", o.tree.sampler.alpha,
                  "density exponent of the subselection: 0 keeps points in proportion to mass, larger values thin "
                  "sparse regions less")->default_val(0.5)->check(CLI::Range(0.0, 4.0));
  cmd->add_option("--seed", o.tree.sampler.seed, "seed of the deterministic sampling hash")->default_val(0);
  cmd->add_option("--coarse", flags->coarse,
                  "what inner nodes hold: 'clusters' (each point a cluster's mass, centre and spread) or 'sample' "
                  "(a random subselection of the points below)")
      ->check(CLI::IsMember({"clusters", "sample"}))
      ->default_val("clusters");
  cmd->add_option("--neighbours", o.neighbours,
                  "leaves' smoothing lengths (where the snapshot has none): the radius of this many nearest "
                  "neighbours, as render --reference draws them; 0: from the leaf's density grid (faster, no "
                  "neighbour pass)")
      ->default_val(kDefaultNeighbours)
      ->check(CLI::Range(0, 4096));
  cmd->add_option("--memory", flags->memory, "memory budget, e.g. 2G (default: half the physical memory)");
  cmd->add_option("--temp-dir", o.temp_dir, "where the temporary directory goes (default: inside the output directory)");
  cmd->add_option("--threads", o.threads, "worker threads (default: one per core this process may run on)")->default_val(0);
  cmd->add_option("--page-size", flags->page_size, "page size of the store, a power of two 4K..16M (its ID index: at least 64K)")->default_val("4K");
  cmd->add_option("--cube", flags->cube,
                  "the cube to index, 'x,y,z,size' (default: the periodic box, else the bounding cube); also accepts "
                  "outliers knowingly, at the resolution this cube gives");
  cmd->add_option("--clip-box", flags->clip_box,
                  "keep only the particles inside this box, 'x0,y0,z0,x1,y1,z1' (bounds included), in every epoch; "
                  "the others are counted in the report and the manifest");
  cmd->add_flag("--drop-outliers", o.drop_outliers,
                "where the cube is the bounding cube and a few far particles would cost the others their precision "
                "(which ingest otherwise refuses, docs/INGEST.md), drop the particles outside the bulk instead");
  AddReadFlags(*cmd, flags->read);
  // What ingest does with what it does not read.
  cmd->get_option("--no-velocity")->description("do not store velocities");
  cmd->get_option("--no-ids")->description("do not store particle IDs (no ID index, no displacements)");
  cmd->add_flag("-q,--quiet", o.quiet, "no progress output");
  cmd->callback([flags] {
    IngestOptions& options = flags->options;
    if (!flags->memory.empty()) options.memory_budget = ParseByteSize(flags->memory, "--memory");
    const std::uint64_t page_size = ParseByteSize(flags->page_size, "--page-size");
    // Checked here, before the narrowing below could turn 4G into 0.
    if (!IsValidPageSize(page_size)) {
      throw Error::InvalidArgument("--page-size '" + flags->page_size + "': " + std::to_string(page_size) +
                                   " bytes is not a power of two from 4K to 16M");
    }
    options.page_size = static_cast<std::uint32_t>(page_size);
    options.read = ReadOptionsFrom(flags->read);
    options.tree.coarse = flags->coarse == "sample" ? CoarsePoints::kSample : CoarsePoints::kClusters;
    if (!flags->cube.empty()) {
      const auto v = ParseNumberList(flags->cube, "--cube");
      if (v.size() != 4) throw Error::InvalidArgument("--cube '" + flags->cube + "': expected x,y,z,size");
      options.cube = Cube{{v[0], v[1], v[2]}, v[3], false};
    }
    if (!flags->clip_box.empty()) {
      const auto v = ParseNumberList(flags->clip_box, "--clip-box");
      if (v.size() != 6) throw Error::InvalidArgument("--clip-box '" + flags->clip_box + "': expected x0,y0,z0,x1,y1,z1");
      options.clip_box = PositionBox{{v[0], v[1], v[2]}, {v[3], v[4], v[5]}};
    }
    const int processes = LaunchedProcesses();
    std::optional<IngestReport> ranked;
    if (processes > 1) {
      ranked = IngestOnRanks(options);
      if (!ranked) return;  // a rank other than 0: rank 0 reports
    }
    const IngestReport report = ranked ? std::move(*ranked) : Ingest(options);
    std::printf("ingested %s points in %zu epoch(s) into %s: %s, %.1f s, %.2f M points/s%s\n",
                HumanCount(static_cast<double>(report.input_points)).c_str(), report.epochs.size(),
                options.output.c_str(), HumanBytes(static_cast<double>(report.store_bytes)).c_str(), report.seconds,
                report.seconds > 0 ? static_cast<double>(report.input_points) / report.seconds / 1e6 : 0.0,
                processes > 1 ? (" on " + std::to_string(processes) + " MPI ranks").c_str() : "");
    if (report.dropped_points) {
      std::printf("  read %llu points, dropped %llu (outside --clip-box or outliers), stored %llu\n",
                  static_cast<unsigned long long>(report.read_points),
                  static_cast<unsigned long long>(report.dropped_points),
                  static_cast<unsigned long long>(report.input_points));
    }
    for (std::size_t e = 0; e < report.epochs.size(); ++e) {
      const EpochReport& r = report.epochs[e];
      std::printf("  epoch %zu: %llu points, %llu nodes (%llu leaves), depth %d, %llu chunks, mass %.9g",
                  e, static_cast<unsigned long long>(r.points), static_cast<unsigned long long>(r.nodes),
                  static_cast<unsigned long long>(r.leaves), r.depth, static_cast<unsigned long long>(r.chunks), r.mass);
      if (r.dropped_points) {
        std::printf(", %llu of the %llu points read dropped", static_cast<unsigned long long>(r.dropped_points),
                    static_cast<unsigned long long>(r.read_points));
      }
      if (r.resident) std::printf(r.mapped ? ", held in memory whole (mapped from its files)" : ", held in memory whole");
      if (r.spilled_points) std::printf(", %llu points spilled to disk", static_cast<unsigned long long>(r.spilled_points));
      if (r.missing_in_next) std::printf(", %llu IDs missing in the next epoch", static_cast<unsigned long long>(r.missing_in_next));
      if (r.missing_in_prev) std::printf(", %llu IDs missing in the previous epoch", static_cast<unsigned long long>(r.missing_in_prev));
      if (r.to_next) std::printf(", velocity scale to the next epoch %.6g (fit residual %.3g)", r.to_next->velocity_scale, r.to_next->fit_residual);
      if (r.duplicate_ids) std::printf(", %llu duplicate IDs", static_cast<unsigned long long>(r.duplicate_ids));
      if (r.ids_sorted) std::printf(", ID pairs sorted (IDs repeat, or their range outgrows a tenth of the budget)");
      std::printf("\n    seconds (CPU):");
      for (const EpochReport::Phase& phase : r.phases) {
        std::printf(" %s %.2f (%.2f)", phase.name.c_str(), phase.seconds, phase.cpu_seconds);
      }
      std::printf("\n");
    }
  });
}

}  // namespace octocosm
