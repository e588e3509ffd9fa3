// The large-scale structure the scale mode samples from, drawn once from the
// seed and shared read-only by every thread: a skeleton of nodes joined by
// filaments, halos on it, and how many particles each structure receives.
//
// The model (docs/SYNTH.md, "Scale mode"):
// - Nodes are uniform in the periodic box; each is joined by a straight
//   filament to its 3 nearest neighbours (minimal-image distance).
// - Halo masses follow dN/dM ~ M^-slope on [M_min, M_min * mass_range]. The
//   heaviest halos sit on the nodes (one each); the others on a filament
//   chosen in proportion to its length, at a uniform point along it, scattered
//   by a 3D Gaussian of the filament radius.
// - Particles are shared out exactly: halo i gets a share of the halo
//   particles proportional to its drawn mass, filament j a share of the
//   filament particles proportional to its length (cumulative rounding, so the
//   shares add up). A halo's mass is then its particle count times the
//   particle mass, and its r_200, concentration and velocity dispersion
//   follow from that mass.
// The particles are numbered in one "structure sequence": the halos' in halo
// order, then the filaments', then the background's (see ScaleSampler).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "synth/nfw_profile.h"
#include "synth/scale_options.h"

namespace octocosm::synth {

// Mean comoving density of the universe is Omega_m times this, in GADGET mass
// units per volume: 1e10 Msun/h per (Mpc/h)^3 (3 H0^2 / 8 pi G).
inline constexpr double kCriticalDensity = 27.7536627;
// Newton's constant in Mpc (km/s)^2 / Msun.
inline constexpr double kGravitationalConstant = 4.30091e-9;
// One-dimensional velocity dispersions of the structures' bulk motions and of
// the particles outside halos, km/s.
inline constexpr double kHaloBulkVelocityDispersion = 300.0;
inline constexpr double kFilamentVelocityDispersion = 200.0;
inline constexpr double kBackgroundVelocityDispersion = 100.0;

struct ScaleHalo {
  std::array<double, 3> center{};        // Mpc/h, inside [0, L)
  std::array<float, 3> bulk_velocity{};  // km/s
  double r200 = 0.0;                     // Mpc/h: mean density inside is 200 Omega_m rho_crit
  float velocity_dispersion = 0.0f;      // 1D, km/s: V_200 / sqrt(2)
  int concentration_index = 0;           // into CosmicWeb::nfw
  std::uint64_t first = 0;               // its first particle in the structure sequence
  std::uint64_t count = 0;               // its particles (may be 0 for the lightest)
};

struct ScaleFilament {
  std::array<double, 3> start{};  // a node, Mpc/h
  std::array<double, 3> axis{};   // minimal-image vector to the other node
  std::array<double, 3> normal1{}, normal2{};  // unit vectors spanning the cross-section
  std::uint64_t first = 0;
  std::uint64_t count = 0;
};

struct CosmicWeb {
  double box_size = 0.0;          // Mpc/h
  double particle_mass = 0.0;     // 1e10 Msun/h: Omega_m rho_crit L^3 / N
  double filament_radius = 0.0;   // Mpc/h
  std::vector<std::array<double, 3>> nodes;
  std::vector<ScaleHalo> halos;
  std::vector<ScaleFilament> filaments;
  std::uint64_t halo_particles = 0;      // structure sequence: [0, halo_particles) are in halos,
  std::uint64_t filament_particles = 0;  // then filament_particles in filaments,
  std::uint64_t background_particles = 0;  // then the uniform background
  NfwRadiusTable nfw;
};

// Draws the web for validated options. Deterministic in options.seed; takes
// O(nodes^2 + halos log halos) time and O(nodes + halos) memory.
CosmicWeb BuildCosmicWeb(const ScaleOptions& options);

}  // namespace octocosm::synth
