// Draws the particles of the scale mode, one chunk at a time, from a shared
// CosmicWeb.
//
// The N particles form a "structure sequence" (cosmic_web.h): position j
// belongs to a halo, a filament or the background, and gets ID j + 1. File f
// of F holds the positions j = f, f + F, f + 2F, ... : a stride-F sample of
// the sequence, so every file holds about 1/F of every halo and filament and
// covers the whole box, and the files' sizes differ by at most one. A file is
// cut into chunks of a fixed size; the particles of chunk k of file f come
// from a random stream seeded by (seed, f, k) alone. Chunks are therefore
// independent: any thread can draw any chunk, and the snapshot does not
// depend on the thread count or on the order chunks are drawn in.
//
// Per particle, given its structure:
// - halo: radius from the halo's truncated NFW profile (inverse transform,
//   nfw_profile.h), isotropic direction; velocity = the halo's bulk velocity
//   plus an isotropic Gaussian of the halo's dispersion;
// - filament: uniform along the segment, 2D Gaussian across it of sigma =
//   the filament radius; Gaussian velocity (kFilamentVelocityDispersion);
// - background: uniform in the box; Gaussian velocity
//   (kBackgroundVelocityDispersion).
// Positions are wrapped into [0, L) and scaled to the output length unit.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "synth/cosmic_web.h"

namespace octocosm::synth {

struct ScaleChunk {
  std::vector<float> positions;   // x,y,z per particle, output length unit, in [0, box)
  std::vector<float> velocities;  // x,y,z per particle, km/s
  std::vector<std::uint64_t> ids;  // 1..N, increasing within a chunk
};

class ScaleSampler {
 public:
  // `web` must outlive the sampler. length_scale converts Mpc/h to the output
  // unit (1000 for kpc/h).
  ScaleSampler(const CosmicWeb& web, std::uint64_t seed, int files, std::size_t chunk_particles, double length_scale);

  std::uint64_t particle_count() const { return particle_count_; }
  int files() const { return files_; }
  std::uint64_t FileParticleCount(int file) const;
  std::uint64_t ChunkCount(int file) const;

  // Replaces `out` with chunk `chunk` of file `file`. Thread-safe (const).
  void Fill(int file, std::uint64_t chunk, ScaleChunk& out) const;

 private:
  const CosmicWeb& web_;
  std::uint64_t seed_;
  int files_;
  std::size_t chunk_particles_;
  double length_scale_;
  float box_out_;  // box side in the output unit
  std::uint64_t particle_count_;
};

}  // namespace octocosm::synth
