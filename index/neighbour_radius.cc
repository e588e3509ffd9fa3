#include "index/neighbour_radius.h"

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <nanoflann.hpp>

#include "base/error.h"

namespace octocosm {
namespace {

// nanoflann's view of the interleaved coordinates.
struct PointCloud {
  std::span<const double> positions;

  std::size_t kdtree_get_point_count() const { return positions.size() / 3; }
  double kdtree_get_pt(std::size_t index, std::size_t axis) const { return positions[3 * index + axis]; }
  template <typename Box>
  bool kdtree_get_bbox(Box&) const {
    return false;  // let the tree compute it
  }
};

using KdTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, PointCloud>, PointCloud, 3, std::uint32_t>;

// Leaves of about this many points: a measured balance between the tree's
// depth and the scan of a leaf for k in the tens.
constexpr std::size_t kLeafPoints = 16;

}  // namespace

struct NeighbourRadii::Tree {
  explicit Tree(std::span<const double> positions)
      : cloud{positions}, index(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(kLeafPoints)) {
    index.buildIndex();
  }
  PointCloud cloud;
  KdTree index;
};

NeighbourRadii::NeighbourRadii(std::span<const double> positions) : count_(positions.size() / 3) {
  if (positions.size() % 3 != 0) {
    throw Error::InvalidArgument("NeighbourRadii: " + std::to_string(positions.size()) +
                                 " coordinates are not a whole number of points");
  }
  if (count_ > std::numeric_limits<std::uint32_t>::max()) {
    throw Error::InvalidArgument("NeighbourRadii: " + std::to_string(count_) + " points exceed 2^32 - 1");
  }
  if (count_ > 0) tree_ = std::make_unique<Tree>(positions);
}

NeighbourRadii::~NeighbourRadii() = default;

double NeighbourRadii::Radius(const double* query, int k) const {
  if (k < 1) throw Error::InvalidArgument("NeighbourRadii: k must be at least 1, not " + std::to_string(k));
  if (count_ < static_cast<std::size_t>(k)) return std::numeric_limits<double>::infinity();
  thread_local std::vector<std::uint32_t> indices;
  thread_local std::vector<double> squared;
  indices.resize(static_cast<std::size_t>(k));
  squared.resize(static_cast<std::size_t>(k));
  nanoflann::KNNResultSet<double, std::uint32_t> result(static_cast<std::size_t>(k));
  result.init(indices.data(), squared.data());
  tree_->index.findNeighbors(result, query, nanoflann::SearchParams());
  return std::sqrt(squared[static_cast<std::size_t>(k) - 1]);
}

}  // namespace octocosm
