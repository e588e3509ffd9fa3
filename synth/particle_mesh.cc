#include "synth/particle_mesh.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "base/error.h"
#include "synth/pm_simulation.h"

namespace octocosm::synth {
namespace {

// Epochs closer than this (relative) are the same epoch: merging them avoids
// a degenerate step of zero length.
constexpr double kSameEpoch = 1e-9;

void Validate(const PmOptions& o) {
  if (!(std::isfinite(o.z_start) && o.z_start > 0.0 && o.z_start < 1e4)) {
    throw Error::InvalidArgument("starting redshift must be in (0, 10000), got " + std::to_string(o.z_start));
  }
  if (!(std::isfinite(o.z_end) && o.z_end >= 0.0 && o.z_end < o.z_start)) {
    throw Error::InvalidArgument("final redshift must be in [0, z_start), got " + std::to_string(o.z_end));
  }
  if (o.steps < 1 || o.steps > 100000) {
    throw Error::InvalidArgument("step count must be in [1, 100000], got " + std::to_string(o.steps));
  }
  if (o.output_redshifts.empty() && (o.output_count < 1 || o.output_count > 10000)) {
    throw Error::InvalidArgument("output count must be in [1, 10000], got " + std::to_string(o.output_count));
  }
  for (double z : o.output_redshifts) {
    // A tolerance so that "--outputs 49,0" with z_start = 49 is accepted.
    if (!(std::isfinite(z) && z >= o.z_end - 1e-9 && z <= o.z_start + 1e-9)) {
      throw Error::InvalidArgument("output redshift " + std::to_string(z) + " is outside [z_end, z_start] = [" +
                                   std::to_string(o.z_end) + ", " + std::to_string(o.z_start) + "]");
    }
  }
  const double particles = std::pow(static_cast<double>(o.particles_per_side), 3);
  if (o.files_per_snapshot < 1 || o.files_per_snapshot > particles) {
    throw Error::InvalidArgument("files per snapshot must be in [1, N^3], got " +
                                 std::to_string(o.files_per_snapshot));
  }
  if (o.snapshot_prefix.empty() || o.snapshot_prefix.find('/') != std::string::npos) {
    throw Error::InvalidArgument("snapshot prefix must be a non-empty file name without '/', got '" +
                                 o.snapshot_prefix + "'");
  }
  std::error_code error;
  if (!std::filesystem::is_directory(o.output_directory, error)) {
    throw Error::NotFound("output directory " + o.output_directory);
  }
}

std::vector<double> MergeEpochs(std::vector<double> epochs) {
  std::sort(epochs.begin(), epochs.end());
  std::vector<double> merged;
  for (double a : epochs) {
    if (merged.empty() || a - merged.back() > kSameEpoch * a) merged.push_back(a);
  }
  return merged;
}

std::string SnapshotBase(const PmOptions& options, std::size_t index) {
  char number[32];
  std::snprintf(number, sizeof number, "_%03zu", index);
  return (std::filesystem::path(options.output_directory) / (options.snapshot_prefix + number)).string();
}

std::vector<std::string> WriteSnapshot(const PmSimulation& simulation, const PmOptions& options, std::size_t index) {
  const double unit = options.output_unit == LengthUnit::kKpcPerH ? 1000.0 : 1.0;
  const double box = options.box_size_mpc_h * unit;
  const CosmologyParameters& cosmology = simulation.cosmology().parameters();
  GadgetSnapshotInfo info;
  info.particle_count = simulation.particle_count();
  info.particle_type = 1;
  info.particle_mass = simulation.ParticleMass();
  info.time = simulation.a();
  info.redshift = 1.0 / simulation.a() - 1.0;
  info.box_size = box;
  info.omega0 = cosmology.omega_matter;
  info.omega_lambda = cosmology.omega_lambda;
  info.hubble_param = cosmology.hubble;
  info.num_files = options.files_per_snapshot;
  GadgetSnapshotWriter writer(SnapshotBase(options, index), info, options.format);

  const float float_box = static_cast<float>(box);
  const double velocity_factor = simulation.GadgetVelocityFactor();
  constexpr std::size_t kChunk = 1 << 16;
  std::vector<float> positions, velocities;
  std::vector<std::uint64_t> ids;
  const auto x = simulation.positions();
  const auto p = simulation.momenta();
  for (std::size_t first = 0; first < info.particle_count; first += kChunk) {
    const std::size_t count = std::min<std::size_t>(kChunk, info.particle_count - first);
    positions.resize(3 * count);
    velocities.resize(3 * count);
    ids.resize(count);
    for (std::size_t i = 0; i < count; ++i) {
      for (int d = 0; d < 3; ++d) {
        positions[3 * i + d] = PositionToFloat(x[3 * (first + i) + d] * unit, float_box);
        velocities[3 * i + d] = static_cast<float>(p[3 * (first + i) + d] * velocity_factor);
      }
      ids[i] = first + i + 1;
    }
    writer.Append(positions, velocities, ids);
  }
  writer.Finish();
  return writer.paths();
}

}  // namespace

std::vector<double> OutputEpochs(const PmOptions& options) {
  Validate(options);
  const double a_start = 1.0 / (1.0 + options.z_start);
  const double a_end = 1.0 / (1.0 + options.z_end);
  std::vector<double> epochs;
  if (!options.output_redshifts.empty()) {
    for (double z : options.output_redshifts) epochs.push_back(std::clamp(1.0 / (1.0 + z), a_start, a_end));
  } else if (options.output_count == 1) {
    epochs.push_back(a_end);
  } else {
    for (int i = 0; i < options.output_count; ++i) {
      epochs.push_back(i + 1 == options.output_count ? a_end
                                                     : a_start + (a_end - a_start) * i / (options.output_count - 1));
    }
  }
  return MergeEpochs(epochs);
}

std::vector<double> StepSchedule(const PmOptions& options) {
  Validate(options);
  const double a_start = 1.0 / (1.0 + options.z_start);
  const double a_end = 1.0 / (1.0 + options.z_end);
  std::vector<double> boundaries;
  for (int i = 1; i <= options.steps; ++i) {
    const double t = static_cast<double>(i) / options.steps;
    if (i == options.steps) {
      boundaries.push_back(a_end);
    } else if (options.step_spacing == StepSpacing::kLinearInA) {
      boundaries.push_back(a_start + (a_end - a_start) * t);
    } else {
      boundaries.push_back(a_start * std::pow(a_end / a_start, t));
    }
  }
  for (double a : OutputEpochs(options)) {
    if (a > a_start * (1.0 + kSameEpoch)) boundaries.push_back(a);
  }
  return MergeEpochs(boundaries);
}

std::vector<PmSnapshotRecord> RunParticleMesh(const PmOptions& options,
                                              const std::function<void(const PmProgress&)>& progress) {
  const auto started = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count(); };
  const std::vector<double> outputs = OutputEpochs(options);
  const std::vector<double> schedule = StepSchedule(options);

  PmSimulationOptions simulation_options;
  simulation_options.particles_per_side = options.particles_per_side;
  simulation_options.grid_factor = options.grid_factor;
  simulation_options.box_size = options.box_size_mpc_h;
  simulation_options.cosmology = options.cosmology;
  simulation_options.seed = options.seed;
  simulation_options.a_start = 1.0 / (1.0 + options.z_start);
  simulation_options.deconvolve_cic = options.deconvolve_cic;
  simulation_options.threads = options.threads;
  PmSimulation simulation(simulation_options);

  PmProgress report;
  report.total_steps = schedule.size();
  report.a = simulation.a();
  report.elapsed_seconds = elapsed();
  report.event = PmProgress::Event::kInitialConditions;
  if (progress) progress(report);

  std::vector<PmSnapshotRecord> written;
  auto write = [&] {
    PmSnapshotRecord record{simulation.a(), 1.0 / simulation.a() - 1.0,
                            WriteSnapshot(simulation, options, written.size())};
    written.push_back(record);
    if (progress) {
      report.event = PmProgress::Event::kSnapshot;
      report.a = simulation.a();
      report.elapsed_seconds = elapsed();
      report.snapshot_files = record.files;
      progress(report);
      report.snapshot_files.clear();
    }
  };

  std::size_t next_output = 0;
  if (outputs[0] <= simulation.a() * (1.0 + kSameEpoch)) {
    write();
    next_output = 1;
  }
  std::size_t step = 0;
  while (next_output < outputs.size()) {
    // Steps up to and including the next output epoch, which the schedule
    // holds as a boundary.
    std::size_t end = step;
    while (end < schedule.size() && schedule[end] < outputs[next_output] * (1.0 - kSameEpoch)) ++end;
    if (end < schedule.size()) ++end;
    const std::span<const double> span(schedule.data() + step, end - step);
    simulation.Evolve(span, [&](std::size_t, double a) {
      ++report.step;
      if (progress) {
        report.event = PmProgress::Event::kStep;
        report.a = a;
        report.elapsed_seconds = elapsed();
        progress(report);
      }
    });
    step = end;
    write();
    ++next_output;
  }
  return written;
}

}  // namespace octocosm::synth
