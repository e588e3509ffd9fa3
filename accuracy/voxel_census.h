// The occupied voxels of a point set, found by pcl::VoxelGrid, with the exact
// mass and count in each and the voxel of every point: the reference against
// which a level-of-detail sample is scored (accuracy/sample_score.h).
//
// The voxels are the cells of a 2^bits grid over an octocosm cube, i.e. the
// cells of octree level `bits`. pcl::VoxelGrid computes a voxel as
// floor(x * (1 / leaf)) in float32, anchored at 0. For its voxels to be
// exactly octocosm's cells the cube must be dyadic: its size a power of two,
// the voxel edge size / 2^bits a float32 value, and each origin coordinate an
// integer multiple of that edge (with |origin| / edge + 2^bits < 2^30, so the
// integers fit). Then 1 / leaf is exact, x * (1 / leaf) is exact for float32
// x, and floor(x / edge) - origin / edge = floor((x - origin) / edge), which is
// octocosm's cell. The census checks this on every point: points PCL puts in
// one voxel must have one octocosm cell, and each tile must hold as many
// voxels as distinct cells; a disagreement is counted, not hidden.
//
// VoxelGrid refuses grids with more than 2^31 voxels in the data's bounding
// box, and its leaf layout (needed to find a point's voxel) is one int per
// voxel of that box. So the census runs VoxelGrid once per tile, an octree
// cell of level bits - 6 (a 64^3 voxel box at most): voxels nest in tiles
// exactly, so no voxel is split or counted twice.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "index/cube.h"

namespace octocosm::accuracy {

struct VoxelCensus {
  int bits = 0;                        // voxels are the cells of level `bits`
  std::vector<std::uint32_t> voxel_of; // per point: its voxel, an index into the per-voxel arrays
  std::vector<double> mass;            // per voxel: total mass of its points
  std::vector<std::uint32_t> count;    // per voxel: its points
  double total_mass = 0;
  std::size_t tiles = 0;               // VoxelGrid runs
  // Points whose PCL voxel and octocosm cell disagree (see above); 0 when
  // the two grids are the same, which the tests assert.
  std::size_t disagreements = 0;

  std::size_t voxels() const { return mass.size(); }
};

// The census of `position` (x,y,z interleaved, float32 values inside the
// cube) with masses `mass`, on the grid of level `bits` (0..kMaxLevel).
// Throws Error::InvalidArgument when the cube is not dyadic as described
// above, a coordinate is not a float32 value or lies outside the cube, or the
// lengths disagree.
VoxelCensus CountVoxels(const std::vector<double>& position, const std::vector<double>& mass, const Cube& cube,
                        int bits);

}  // namespace octocosm::accuracy
