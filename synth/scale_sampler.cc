#include "synth/scale_sampler.h"

#include <algorithm>
#include <cmath>

#include "base/hash.h"
#include "synth/gadget_writer.h"
#include "synth/random.h"

namespace octocosm::synth {
namespace {

// Each chunk's stream from its own seed, so that files and chunks can be
// generated in any order and on any thread.
std::uint64_t ChunkSeed(std::uint64_t seed, int file, std::uint64_t chunk) {
  return MixBits64(MixBits64(MixBits64(seed) ^ static_cast<std::uint64_t>(file)) + chunk);
}

// Into [0, box). Structures reach less than a box length outside it, so one
// addition or subtraction almost always does; the division is the fallback.
double Wrap(double x, double box) {
  if (x < 0.0) {
    x += box;
  } else if (x >= box) {
    x -= box;
  }
  if (x >= 0.0 && x < box) return x;
  x -= box * std::floor(x / box);
  return x < box ? x : 0.0;  // a hair below 0 can round up to box
}

}  // namespace

ScaleSampler::ScaleSampler(const CosmicWeb& web, std::uint64_t seed, int files, std::size_t chunk_particles,
                           double length_scale)
    : web_(web),
      seed_(seed),
      files_(files),
      chunk_particles_(chunk_particles),
      length_scale_(length_scale),
      box_out_(static_cast<float>(web.box_size * length_scale)),
      particle_count_(web.halo_particles + web.filament_particles + web.background_particles) {}

std::uint64_t ScaleSampler::FileParticleCount(int file) const {
  const std::uint64_t f = static_cast<std::uint64_t>(file);
  const std::uint64_t stride = static_cast<std::uint64_t>(files_);
  return f >= particle_count_ ? 0 : (particle_count_ - f + stride - 1) / stride;
}

std::uint64_t ScaleSampler::ChunkCount(int file) const {
  return (FileParticleCount(file) + chunk_particles_ - 1) / chunk_particles_;
}

void ScaleSampler::Fill(int file, std::uint64_t chunk, ScaleChunk& out) const {
  const std::uint64_t file_count = FileParticleCount(file);
  const std::uint64_t begin = std::min<std::uint64_t>(file_count, chunk * chunk_particles_);
  const std::uint64_t end = std::min<std::uint64_t>(file_count, begin + chunk_particles_);
  const std::size_t count = static_cast<std::size_t>(end - begin);
  out.positions.resize(3 * count);
  out.velocities.resize(3 * count);
  out.ids.resize(count);
  if (count == 0) return;

  Random random(ChunkSeed(seed_, file, chunk));
  const double box = web_.box_size;
  const std::uint64_t stride = static_cast<std::uint64_t>(files_);
  const std::uint64_t filaments_begin = web_.halo_particles;
  const std::uint64_t background_begin = web_.halo_particles + web_.filament_particles;
  const std::uint64_t first_position = static_cast<std::uint64_t>(file) + stride * begin;

  // Cursors into the halo and filament lists: the structure holding the
  // current sequence position, advanced as the positions increase.
  auto by_first = [](std::uint64_t j, const auto& structure) { return j < structure.first; };
  std::size_t halo = 0;
  if (first_position < filaments_begin) {
    halo = static_cast<std::size_t>(std::upper_bound(web_.halos.begin(), web_.halos.end(), first_position, by_first) -
                                    web_.halos.begin()) - 1;
  }
  std::size_t filament = 0;
  if (first_position >= filaments_begin && first_position < background_begin) {
    filament = static_cast<std::size_t>(std::upper_bound(web_.filaments.begin(), web_.filaments.end(),
                                                         first_position, by_first) -
                                        web_.filaments.begin()) - 1;
  }

  for (std::size_t i = 0; i < count; ++i) {
    const std::uint64_t j = first_position + stride * i;
    double p[3];
    double v[3];
    if (j < filaments_begin) {
      while (j >= web_.halos[halo].first + web_.halos[halo].count) ++halo;
      const ScaleHalo& h = web_.halos[halo];
      const double r = h.r200 * web_.nfw.Radius(h.concentration_index, random.Uniform());
      const auto direction = random.Direction();
      for (int k = 0; k < 3; ++k) p[k] = h.center[k] + r * direction[k];
      for (int k = 0; k < 3; ++k) v[k] = h.bulk_velocity[k] + h.velocity_dispersion * random.Gaussian();
    } else if (j < background_begin) {
      while (j >= web_.filaments[filament].first + web_.filaments[filament].count) ++filament;
      const ScaleFilament& f = web_.filaments[filament];
      const double t = random.Uniform();
      const double a = web_.filament_radius * random.Gaussian();
      const double b = web_.filament_radius * random.Gaussian();
      for (int k = 0; k < 3; ++k) p[k] = f.start[k] + t * f.axis[k] + a * f.normal1[k] + b * f.normal2[k];
      for (int k = 0; k < 3; ++k) v[k] = kFilamentVelocityDispersion * random.Gaussian();
    } else {
      for (int k = 0; k < 3; ++k) p[k] = random.Uniform() * box;
      for (int k = 0; k < 3; ++k) v[k] = kBackgroundVelocityDispersion * random.Gaussian();
    }
    for (int k = 0; k < 3; ++k) {
      out.positions[3 * i + k] = PositionToFloat(Wrap(p[k], box) * length_scale_, box_out_);
      out.velocities[3 * i + k] = static_cast<float>(v[k]);
    }
    out.ids[i] = j + 1;
  }
}

}  // namespace octocosm::synth
