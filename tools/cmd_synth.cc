// octocosm synth: realistic simulations written as GADGET-2 snapshots.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "synth/particle_mesh.h"
#include "synth/scale_generator.h"
#include "tools/cli_util.h"
#include "tools/commands.h"

namespace octocosm {

namespace {

void AddSynthScaleCommand(CLI::App& synth) {
  auto scale = std::make_shared<synth::ScaleOptions>();
  auto format = std::make_shared<int>(2);
  auto unit = std::make_shared<std::string>("kpc");
  auto quiet = std::make_shared<bool>(false);
  CLI::App* cmd = synth.add_subcommand(
      "scale",
      "A fast clustered point set for 10^8..10^10 particles: halos with a power-law mass function and NFW\n"
      "profiles on a skeleton of filaments, filament particles and a uniform background, in a periodic box.\n"
      "Memory stays O(halos + threads x chunk). Writes a multi-file GADGET snapshot <prefix>.0 .. <prefix>.K-1\n"
      "(one file: <prefix>), readable by 'octocosm ingest DIR/<prefix>'.");
  cmd->add_option("-o,--output", scale->output_directory, "directory for the snapshot (created)")->required();
  cmd->add_option("-n,--particles", scale->particle_count, "number of particles")->default_val(100'000'000)
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 40));
  cmd->add_option("--box", scale->box_size_mpc_h, "periodic box side in Mpc/h")->default_val(500.0)->check(CLI::PositiveNumber);
  auto* files = cmd->add_option("--files", scale->files, "number of files (default: max(8, n / 2^25))")->check(CLI::Range(1, 1'000'000));
  cmd->add_option("--particles-per-file", scale->particles_per_file, "at most this many particles per file")
      ->check(CLI::Range(std::uint64_t{1}, synth::kMaxScaleParticlesPerFile))->excludes(files);
  cmd->add_option("--seed", scale->seed, "random seed")->default_val(1);
  cmd->add_option("--halo-fraction", scale->halo_fraction, "share of the particles in halos")->default_val(0.5)->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--filament-fraction", scale->filament_fraction, "share of the particles in filaments (the rest is uniform)")
      ->default_val(0.3)->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--halos", scale->halo_count, "number of halos (default: one per 500 halo particles, 1..200000)")->default_val(0);
  cmd->add_option("--mass-slope", scale->mass_function_slope, "alpha in dN/dM ~ M^-alpha")->default_val(1.9)->check(CLI::PositiveNumber);
  cmd->add_option("--mass-range", scale->halo_mass_range, "M_max / M_min of the halos")->default_val(1000.0)->check(CLI::Range(1.0, 1e12));
  cmd->add_option("--nodes", scale->node_count, "filament skeleton nodes (default: halos / 16, 16..4096)")->default_val(0);
  cmd->add_option("--filament-radius", scale->filament_radius_mpc_h, "Gaussian sigma of a filament's cross-section, Mpc/h")
      ->default_val(1.0)->check(CLI::PositiveNumber);
  cmd->add_option("--omega-m", scale->omega_matter, "Omega_matter (sets the particle mass and halo radii)")->default_val(0.3)->check(CLI::PositiveNumber);
  cmd->add_option("--omega-l", scale->omega_lambda, "Omega_Lambda (header only)")->default_val(0.7);
  cmd->add_option("--hubble", scale->hubble, "h (header only)")->default_val(0.7);
  cmd->add_option("--prefix", scale->snapshot_prefix, "snapshot file prefix")->default_val("snap");
  cmd->add_option("--format", *format, "GADGET snapshot format 1 or 2")->default_val(2)->check(CLI::Range(1, 2));
  cmd->add_option("--unit", *unit, "length unit of the output: kpc (GADGET default) or mpc (per h)")
      ->check(CLI::IsMember({"kpc", "mpc"}))->default_val("kpc");
  cmd->add_option("--threads", scale->threads, "threads (0 = all); each works on its own file")->default_val(0)->check(CLI::NonNegativeNumber);
  cmd->add_flag("-q,--quiet", *quiet, "no progress output");
  cmd->callback([=] {
    synth::ScaleOptions options = *scale;
    options.format = *format == 1 ? synth::GadgetFormat::kFormat1 : synth::GadgetFormat::kFormat2;
    options.output_unit = *unit == "mpc" ? synth::LengthUnit::kMpcPerH : synth::LengthUnit::kKpcPerH;
    const bool verbose = !*quiet;
    const auto result = synth::RunScaleGenerator(options, [verbose](const synth::ScaleProgress& p) {
      if (!verbose) return;
      std::fprintf(stderr, "synth scale: file %d/%d done (%s), %.1f%% of particles, %.1f s, %.1f M particles/s\n",
                   p.files_done, p.file_count, p.path.c_str(),
                   100.0 * static_cast<double>(p.particles_done) / static_cast<double>(p.particle_count), p.elapsed_seconds,
                   static_cast<double>(p.particles_done) / std::max(p.elapsed_seconds, 1e-9) / 1e6);
    });
    std::printf("%llu particles (mass %.6g x 1e10 Msun/h), %zu halos, %zu filaments (drawn in %.2f s), %zu files, "
                "%d threads, %.2f s, %.1f M particles/s\n",
                static_cast<unsigned long long>(result.particle_count), result.particle_mass, result.halos,
                result.filaments, result.web_seconds, result.files.size(), result.threads, result.total_seconds,
                static_cast<double>(result.particle_count) / std::max(result.total_seconds, 1e-9) / 1e6);
    std::printf("%s%s\n", result.files.front().c_str(),
                result.files.size() > 1 ? (" .. " + result.files.back()).c_str() : "");
  });
}

}  // namespace

void AddSynthCommand(CLI::App& app) {
  CLI::App* synth = app.add_subcommand("synth", "Generate simulations as GADGET-2 snapshots (docs/SYNTH.md).");
  synth->require_subcommand(1);

  auto pm = std::make_shared<synth::PmOptions>();
  auto redshifts = std::make_shared<std::string>();
  auto format = std::make_shared<int>(2);
  auto unit = std::make_shared<std::string>("kpc");
  auto spacing = std::make_shared<std::string>("linear");
  auto quiet = std::make_shared<bool>(false);
  CLI::App* cmd = synth->add_subcommand(
      "pm",
      "A particle-mesh N-body run: Zel'dovich initial conditions from a LCDM power spectrum, PM gravity with\n"
      "FFTW on a periodic comoving grid, kick-drift-kick leapfrog in the expansion factor. Writes one GADGET\n"
      "snapshot per output epoch, <prefix>_<sss>[.<file>], with IDs and velocities.");
  cmd->add_option("-o,--output", pm->output_directory, "directory for the snapshots (created)")->required();
  cmd->add_option("-N,--particles-per-side", pm->particles_per_side, "N: N^3 particles")->default_val(64)->check(CLI::Range(2, 512));
  cmd->add_option("--grid-factor", pm->grid_factor, "PM grid cells per particle per side (1 or 2)")->default_val(2)->check(CLI::Range(1, 2));
  cmd->add_option("--box", pm->box_size_mpc_h, "comoving box side in Mpc/h")->default_val(100.0)->check(CLI::PositiveNumber);
  cmd->add_option("--omega-m", pm->cosmology.omega_matter, "Omega_matter")->default_val(0.3);
  cmd->add_option("--omega-l", pm->cosmology.omega_lambda, "Omega_Lambda")->default_val(0.7);
  cmd->add_option("--omega-b", pm->cosmology.omega_baryon, "Omega_baryon (transfer function only)")->default_val(0.049);
  cmd->add_option("--hubble", pm->cosmology.hubble, "h")->default_val(0.7);
  cmd->add_option("--sigma8", pm->cosmology.sigma8, "sigma8 at z = 0")->default_val(0.8);
  cmd->add_option("--ns", pm->cosmology.spectral_index, "spectral index")->default_val(0.965);
  cmd->add_option("--seed", pm->seed, "random seed of the initial conditions")->default_val(1);
  cmd->add_option("--z-start", pm->z_start, "initial redshift")->default_val(49.0);
  cmd->add_option("--z-end", pm->z_end, "final redshift")->default_val(0.0);
  cmd->add_option("--steps", pm->steps, "leapfrog steps")->default_val(30)->check(CLI::Range(1, 100000));
  cmd->add_option("--step-spacing", *spacing, "linear or log in a")->check(CLI::IsMember({"linear", "log"}))->default_val("linear");
  cmd->add_option("--outputs", pm->output_count, "output epochs evenly spaced in a (the first at z-start)")->default_val(1);
  cmd->add_option("--output-redshifts", *redshifts, "explicit output redshifts, e.g. '9,3,1,0' (overrides --outputs)");
  cmd->add_option("--prefix", pm->snapshot_prefix, "snapshot file prefix")->default_val("snap");
  cmd->add_option("--format", *format, "GADGET snapshot format 1 or 2")->default_val(2)->check(CLI::Range(1, 2));
  cmd->add_option("--files", pm->files_per_snapshot, "files per snapshot")->default_val(1)->check(CLI::Range(1, 4096));
  cmd->add_option("--unit", *unit, "length unit of the output: kpc (GADGET default) or mpc (per h)")
      ->check(CLI::IsMember({"kpc", "mpc"}))->default_val("kpc");
  cmd->add_option("--threads", pm->threads, "threads (0 = all)")->default_val(0);
  cmd->add_flag("-q,--quiet", *quiet, "no progress output");
  cmd->callback([=] {
    synth::PmOptions options = *pm;
    options.format = *format == 1 ? synth::GadgetFormat::kFormat1 : synth::GadgetFormat::kFormat2;
    options.output_unit = *unit == "mpc" ? synth::LengthUnit::kMpcPerH : synth::LengthUnit::kKpcPerH;
    options.step_spacing = *spacing == "log" ? synth::StepSpacing::kLogarithmicInA : synth::StepSpacing::kLinearInA;
    if (!redshifts->empty()) options.output_redshifts = ParseNumberList(*redshifts, "--output-redshifts");
    std::filesystem::create_directories(options.output_directory);
    const bool verbose = !*quiet;
    const auto records = synth::RunParticleMesh(options, [verbose](const synth::PmProgress& p) {
      if (!verbose) return;
      if (p.event == synth::PmProgress::Event::kSnapshot) {
        std::fprintf(stderr, "synth pm: a = %.4f (z = %.3f): wrote %s\n", p.a, 1.0 / p.a - 1.0, p.snapshot_files.front().c_str());
      } else if (p.event == synth::PmProgress::Event::kStep && p.total_steps > 0 && (p.step % 5 == 0 || p.step == p.total_steps)) {
        std::fprintf(stderr, "synth pm: step %zu / %zu, a = %.4f, %.1f s\n", p.step, p.total_steps, p.a, p.elapsed_seconds);
      }
    });
    for (const auto& record : records) {
      std::printf("z = %8.4f  a = %.6f  %s%s\n", record.redshift, record.a, record.files.front().c_str(),
                  record.files.size() > 1 ? (" (+" + std::to_string(record.files.size() - 1) + " files)").c_str() : "");
    }
  });

  AddSynthScaleCommand(*synth);
}

}  // namespace octocosm
