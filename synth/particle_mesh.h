// `octocosm synth` particle-mesh mode: a cosmological N-body run from
// Zel'dovich initial conditions to a chosen redshift, written as GADGET-2
// snapshots at the requested epochs. docs/SYNTH.md documents the physics,
// the units and every option.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "synth/cosmology.h"
#include "synth/gadget_writer.h"

namespace octocosm::synth {

enum class StepSpacing {
  kLinearInA,       // equal steps in a: fine late, where structure is nonlinear
  kLogarithmicInA,  // equal steps in ln a: fine early, where a grows fastest in relative terms
};

enum class LengthUnit {
  kKpcPerH,  // GADGET's default unit; what readers assume without a parameter file
  kMpcPerH,
};

struct PmOptions {
  // Simulation.
  int particles_per_side = 64;     // N: N^3 particles, 2..512
  int grid_factor = 2;             // PM grid of grid_factor * N cells per side: 1 or 2
  double box_size_mpc_h = 100.0;   // comoving box side in Mpc/h (output in output_unit)
  CosmologyParameters cosmology;   // Omega_m, Omega_Lambda, Omega_b, h, sigma8, n_s
  std::uint64_t seed = 1;
  double z_start = 49.0;
  double z_end = 0.0;
  int steps = 30;                  // leapfrog steps from z_start to z_end (output epochs add boundaries)
  StepSpacing step_spacing = StepSpacing::kLinearInA;
  bool deconvolve_cic = false;    // amplifies lattice noise near Nyquist: off unless you know you want it
  int threads = 0;                 // 0: all hardware threads

  // Output epochs: output_redshifts when non-empty (each within
  // [z_end, z_start]), else output_count epochs evenly spaced in a, the last
  // at z_end and, when output_count >= 2, the first at z_start (the initial
  // conditions).
  int output_count = 1;
  std::vector<double> output_redshifts;

  // Files.
  std::string output_directory = ".";   // must exist
  std::string snapshot_prefix = "snap";  // snapshot s is <prefix>_<sss>[.<file>]
  GadgetFormat format = GadgetFormat::kFormat2;
  int files_per_snapshot = 1;
  LengthUnit output_unit = LengthUnit::kKpcPerH;
};

struct PmProgress {
  enum class Event { kInitialConditions, kStep, kSnapshot };
  Event event = Event::kStep;
  std::size_t step = 0;          // steps done so far
  std::size_t total_steps = 0;   // after output epochs were merged into the schedule
  double a = 0.0;
  double elapsed_seconds = 0.0;
  std::vector<std::string> snapshot_files;  // kSnapshot only
};

struct PmSnapshotRecord {
  double a = 0.0;
  double redshift = 0.0;
  std::vector<std::string> files;
};

// The expansion factors of the output epochs described by options, ascending.
std::vector<double> OutputEpochs(const PmOptions& options);
// The step boundaries after a_start: the regular steps merged with the
// output epochs, ascending, ending at a_end.
std::vector<double> StepSchedule(const PmOptions& options);

// Runs the simulation and writes its snapshots. Throws octocosm::Error:
// InvalidArgument for bad options, Io when a file cannot be written.
std::vector<PmSnapshotRecord> RunParticleMesh(const PmOptions& options,
                                              const std::function<void(const PmProgress&)>& progress = nullptr);

}  // namespace octocosm::synth
