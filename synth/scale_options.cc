#include "synth/scale_options.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "base/error.h"

namespace octocosm::synth {

int DefaultScaleFileCount(std::uint64_t particle_count) {
  const std::uint64_t per_file = std::uint64_t{1} << 25;
  const std::uint64_t files = std::max<std::uint64_t>(8, (particle_count + per_file - 1) / per_file);
  return static_cast<int>(std::min<std::uint64_t>(files, std::max<std::uint64_t>(particle_count, 1)));
}

std::size_t DefaultHaloCount(std::uint64_t halo_particles) {
  return static_cast<std::size_t>(std::clamp<std::uint64_t>(halo_particles / 500, 1, 200000));
}

std::size_t DefaultNodeCount(std::size_t halo_count) { return std::clamp<std::size_t>(halo_count / 16, 16, 4096); }

namespace {

constexpr std::uint64_t kMaxFiles = 1'000'000;

std::uint64_t RequestedFileCount(const ScaleOptions& options) {
  if (options.files > 0) return static_cast<std::uint64_t>(options.files);
  if (options.particles_per_file > 0) {
    return (options.particle_count + options.particles_per_file - 1) / options.particles_per_file;
  }
  return static_cast<std::uint64_t>(DefaultScaleFileCount(options.particle_count));
}

}  // namespace

int ResolveScaleFileCount(const ScaleOptions& options) {
  return static_cast<int>(std::min(RequestedFileCount(options), kMaxFiles));  // ValidateScaleOptions rejects more
}

void ValidateScaleOptions(const ScaleOptions& o) {
  auto fail = [](const std::string& what) { throw Error::InvalidArgument("synth scale: " + what); };
  if (o.particle_count == 0) fail("the particle count must be at least 1");
  if (!(o.box_size_mpc_h > 0.0) || !std::isfinite(o.box_size_mpc_h)) fail("the box size must be positive");
  if (o.files < 0) fail("the file count must not be negative");
  if (o.files > 0 && o.particles_per_file > 0) fail("give either a file count or particles per file, not both");
  if (o.particles_per_file > kMaxScaleParticlesPerFile) {
    fail("at most " + std::to_string(kMaxScaleParticlesPerFile) + " particles fit one GADGET file");
  }
  const std::uint64_t requested_files = RequestedFileCount(o);
  if (requested_files > kMaxFiles) fail(std::to_string(requested_files) + " files: at most 10^6");
  const int files = ResolveScaleFileCount(o);
  if (static_cast<std::uint64_t>(files) > o.particle_count) {
    fail(std::to_string(files) + " files for " + std::to_string(o.particle_count) + " particles: every file needs one");
  }
  const std::uint64_t largest_file = (o.particle_count + static_cast<std::uint64_t>(files) - 1) / static_cast<std::uint64_t>(files);
  if (largest_file > kMaxScaleParticlesPerFile) {
    fail(std::to_string(largest_file) + " particles in one file overflow a GADGET record; use more files");
  }
  auto is_fraction = [](double f) { return f >= 0.0 && f <= 1.0; };
  if (!is_fraction(o.halo_fraction)) fail("the halo fraction must be in [0, 1]");
  if (!is_fraction(o.filament_fraction)) fail("the filament fraction must be in [0, 1]");
  if (o.halo_fraction + o.filament_fraction > 1.0 + 1e-12) fail("the halo and filament fractions add up to more than 1");
  if (o.halo_count > 10'000'000) fail("at most 10^7 halos");
  if (!(o.mass_function_slope > 0.0) || !std::isfinite(o.mass_function_slope)) fail("the mass function slope must be positive");
  if (!(o.halo_mass_range >= 1.0) || !std::isfinite(o.halo_mass_range)) fail("the halo mass range must be at least 1");
  if (o.node_count == 1 || o.node_count > 16384) fail("the node count must be 0 (automatic) or 2..16384");
  if (!(o.filament_radius_mpc_h > 0.0) || !std::isfinite(o.filament_radius_mpc_h)) fail("the filament radius must be positive");
  if (!(o.omega_matter > 0.0) || !std::isfinite(o.omega_matter)) fail("Omega_matter must be positive");
  if (o.chunk_particles == 0 || o.chunk_particles > (std::size_t{1} << 24)) fail("the chunk size must be 1..2^24 particles");
  if (o.threads < 0) fail("the thread count must not be negative");
}

}  // namespace octocosm::synth
