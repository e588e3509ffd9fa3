// What `octocosm synth scale` generates: a clustered point set of 10^8 to
// 10^10 particles (halos on a filament skeleton plus a diffuse background) in
// a periodic box, written as a multi-file GADGET-2 snapshot. docs/SYNTH.md
// ("Scale mode") describes the model; ValidateScaleOptions lists the limits.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "synth/gadget_writer.h"
#include "synth/particle_mesh.h"

namespace octocosm::synth {

struct ScaleOptions {
  std::string output_directory;      // created if missing
  std::string snapshot_prefix = "snap";  // files <prefix>.0 .. <prefix>.<F-1>
  std::uint64_t particle_count = 100'000'000;
  double box_size_mpc_h = 500.0;     // periodic box side, comoving Mpc/h
  std::uint64_t seed = 1;

  // Files: `files` when > 0, else ceil(particle_count / particles_per_file)
  // when that is > 0, else DefaultScaleFileCount(); at most 10^6 files.
  int files = 0;
  std::uint64_t particles_per_file = 0;

  // Shares of the particles in halos and in filaments; the rest is a uniform
  // background. Each in [0, 1], their sum at most 1.
  double halo_fraction = 0.5;
  double filament_fraction = 0.3;

  // Halos: count (0 = DefaultHaloCount), mass function dN/dM ~ M^-slope
  // between M_min and M_max = M_min * mass_range.
  std::size_t halo_count = 0;
  double mass_function_slope = 1.9;
  double halo_mass_range = 1000.0;

  // Skeleton: nodes (0 = DefaultNodeCount), each joined by a filament to its
  // 3 nearest neighbours; sigma of the filaments' Gaussian cross-section.
  std::size_t node_count = 0;
  double filament_radius_mpc_h = 1.0;

  double omega_matter = 0.3;   // fixes the particle mass and the halos' r_200
  double omega_lambda = 0.7;   // header only
  double hubble = 0.7;         // header only

  GadgetFormat format = GadgetFormat::kFormat2;
  LengthUnit output_unit = LengthUnit::kKpcPerH;
  int threads = 0;             // 0 = all hardware threads
  std::size_t chunk_particles = std::size_t{1} << 16;  // generated and written at a time, per thread
};

// The most particles one file may hold: its POS block, 12 bytes a particle,
// must fit a GADGET record's int32 byte count.
inline constexpr std::uint64_t kMaxScaleParticlesPerFile = (std::uint64_t{0x7fffffff} - 16) / 12;

// max(8, ceil(particle_count / 2^25)), at most particle_count: files of ~1 GB
// at most, and enough of them for 8 threads to work on at once.
int DefaultScaleFileCount(std::uint64_t particle_count);
// One halo per 500 halo particles, between 1 and 200000.
std::size_t DefaultHaloCount(std::uint64_t halo_particles);
// One node per 16 halos, between 16 and 4096.
std::size_t DefaultNodeCount(std::size_t halo_count);

// The file count the options select (after the rules above).
int ResolveScaleFileCount(const ScaleOptions& options);

// Throws Error::InvalidArgument naming the first option out of range.
void ValidateScaleOptions(const ScaleOptions& options);

}  // namespace octocosm::synth
