#include "accuracy/voxel_census.h"

#include <pcl/filters/voxel_grid.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <unordered_map>

#include "accuracy/pcl_cloud.h"
#include "base/error.h"
#include "index/morton.h"

namespace octocosm::accuracy {
namespace {

constexpr int kTileBits = 6;  // a tile is at most 64^3 voxels

void CheckDyadic(const Cube& cube, int bits) {
  cube.Validate();
  if (bits < 0 || bits > kMaxLevel) throw Error::InvalidArgument("voxel census: bits must be in 0..21");
  int exponent = 0;
  if (std::frexp(cube.size, &exponent) != 0.5) {
    throw Error::InvalidArgument("voxel census: cube size " + std::to_string(cube.size) +
                                 " is not a power of two, so PCL's float voxels would not be octocosm's cells");
  }
  const double edge = std::ldexp(cube.size, -bits);
  if (static_cast<double>(static_cast<float>(edge)) != edge || !std::isnormal(static_cast<float>(edge))) {
    throw Error::InvalidArgument("voxel census: voxel edge " + std::to_string(edge) + " is not a float32 value");
  }
  for (int a = 0; a < 3; ++a) {
    const double cells = cube.origin[a] / edge;
    if (cells != std::floor(cells) || std::fabs(cells) + std::ldexp(1.0, bits) >= std::ldexp(1.0, 30)) {
      throw Error::InvalidArgument("voxel census: cube origin " + std::to_string(cube.origin[a]) +
                                   " is not a whole number of voxel edges (" + std::to_string(edge) +
                                   ") small enough for PCL's int grid");
    }
  }
}

}  // namespace

VoxelCensus CountVoxels(const std::vector<double>& position, const std::vector<double>& mass, const Cube& cube,
                        int bits) {
  CheckDyadic(cube, bits);
  const std::size_t n = mass.size();
  if (position.size() != 3 * n) throw Error::InvalidArgument("voxel census: positions and masses disagree");
  for (std::size_t i = 0; i < 3 * n; ++i) {
    const double x = position[i];
    const double lo = cube.origin[i % 3];
    if (!(x >= lo && x < lo + cube.size)) {
      throw Error::InvalidArgument("voxel census: point " + std::to_string(i / 3) + " lies outside the cube");
    }
  }

  // Points grouped by tile, tiles in key order.
  const int tile_level = std::max(0, bits - kTileBits);
  std::vector<std::uint64_t> tile(n);
  for (std::size_t i = 0; i < n; ++i) tile[i] = cube.LeafKey(&position[3 * i], tile_level).value();
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return tile[a] < tile[b]; });

  VoxelCensus census;
  census.bits = bits;
  census.voxel_of.assign(n, 0);
  const auto edge = static_cast<float>(std::ldexp(cube.size, -bits));
  pcl::VoxelGrid<pcl::PointXYZ> grid;
  grid.setLeafSize(edge, edge, edge);
  grid.setSaveLeafLayout(true);
  pcl::PointCloud<pcl::PointXYZ> centroids;
  for (std::size_t begin = 0; begin < n;) {
    std::size_t end = begin;
    while (end < n && tile[order[end]] == tile[order[begin]]) ++end;
    const std::span<const std::uint32_t> members(order.data() + begin, end - begin);
    const auto cloud = ToFloatCloud(position, members);
    grid.setInputCloud(cloud);
    grid.filter(centroids);
    const std::size_t base = census.mass.size();
    census.mass.resize(base + centroids.size(), 0.0);
    census.count.resize(base + centroids.size(), 0);
    // The octocosm cell of each voxel's first point, to check the others.
    std::vector<std::uint64_t> cell_of_voxel(centroids.size(), 0);
    std::unordered_map<std::uint64_t, int> distinct_cells;
    for (std::size_t k = 0; k < members.size(); ++k) {
      const std::uint32_t i = members[k];
      const int local = grid.getCentroidIndex((*cloud)[k]);
      if (local < 0 || static_cast<std::size_t>(local) >= centroids.size()) {
        throw Error::InvalidArgument("voxel census: PCL found no voxel for point " + std::to_string(i));
      }
      const std::uint64_t cell = cube.LeafKey(&position[3 * i], bits).value();
      ++distinct_cells[cell];
      const std::size_t v = base + static_cast<std::size_t>(local);
      if (census.count[v] == 0) {
        cell_of_voxel[static_cast<std::size_t>(local)] = cell;
      } else if (cell_of_voxel[static_cast<std::size_t>(local)] != cell) {
        ++census.disagreements;
      }
      census.voxel_of[i] = static_cast<std::uint32_t>(v);
      census.mass[v] += mass[i];
      ++census.count[v];
      census.total_mass += mass[i];
    }
    if (distinct_cells.size() != centroids.size()) {
      census.disagreements += distinct_cells.size() > centroids.size() ? distinct_cells.size() - centroids.size()
                                                                       : centroids.size() - distinct_cells.size();
    }
    ++census.tiles;
    begin = end;
  }
  return census;
}

}  // namespace octocosm::accuracy
