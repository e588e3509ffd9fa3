#include "index/neighbour_radius.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <nanoflann.hpp>

#include "base/error.h"
#include "base/parallel_for.h"

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

// The k smallest squared distances seen, in ascending order, nanoflann's
// KNNResultSet without the indices and with a starting bound: until it holds
// k distances, only those below the bound are offered, so the search prunes
// from its first step.
class BoundedKnnSet {
 public:
  using DistanceType = double;
  using IndexType = std::uint32_t;
  using CountType = std::size_t;

  BoundedKnnSet(double* distances, std::size_t k, double squared_bound) : distances_(distances), k_(k) {
    distances_[k_ - 1] = squared_bound;
  }
  std::size_t size() const { return count_; }
  bool full() const { return count_ == k_; }
  // While not full, the last slot holds the bound: insertions below only
  // reach it when the k-th distance arrives.
  double worstDist() const { return distances_[k_ - 1]; }
  bool addPoint(double distance, std::uint32_t) {
    std::size_t i = count_;
    for (; i > 0 && distances_[i - 1] > distance; --i) {
      if (i < k_) distances_[i] = distances_[i - 1];
    }
    if (i < k_) distances_[i] = distance;
    if (count_ < k_) ++count_;
    return true;
  }

 private:
  double* distances_;
  std::size_t k_;
  std::size_t count_ = 0;
};

// Leaves of about this many points: a measured balance between the tree's
// depth and the scan of a leaf for k in the tens.
constexpr std::size_t kLeafPoints = 16;

}  // namespace

struct NeighbourRadii::Block {
  explicit Block(std::span<const double> positions)
      : cloud{positions}, index(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(kLeafPoints)) {
    index.buildIndex();
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::numeric_limits<double>::infinity();
      hi[a] = -std::numeric_limits<double>::infinity();
    }
    for (std::size_t i = 0; i < positions.size(); i += 3) {
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], positions[i + a]);
        hi[a] = std::max(hi[a], positions[i + a]);
      }
    }
  }
  // Squared distance from `p` to the block's bounding box.
  double SquaredDistance(const double* p) const {
    double d2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double d = std::max({lo[a] - p[a], 0.0, p[a] - hi[a]});
      d2 += d * d;
    }
    return d2;
  }
  PointCloud cloud;
  KdTree index;
  double lo[3], hi[3];
};

NeighbourRadii::NeighbourRadii(std::span<const double> positions, std::span<const std::size_t> block_begins,
                               int threads)
    : count_(positions.size() / 3) {
  if (positions.size() % 3 != 0) {
    throw Error::InvalidArgument("NeighbourRadii: " + std::to_string(positions.size()) +
                                 " coordinates are not a whole number of points");
  }
  if (count_ > std::numeric_limits<std::uint32_t>::max()) {
    throw Error::InvalidArgument("NeighbourRadii: " + std::to_string(count_) + " points exceed 2^32 - 1");
  }
  if (count_ == 0) return;
  std::vector<std::size_t> begins(block_begins.begin(), block_begins.end());
  if (begins.empty()) begins.push_back(0);
  for (std::size_t b = 0; b < begins.size(); ++b) {
    const std::size_t end = b + 1 < begins.size() ? begins[b + 1] : count_;
    if ((b == 0 && begins[b] != 0) || begins[b] >= end) {
      throw Error::InvalidArgument("NeighbourRadii: block " + std::to_string(b) + " starts at point " +
                                   std::to_string(begins[b]) + ": blocks must start at 0, ascend and not be empty");
    }
  }
  blocks_.resize(begins.size());
  ParallelForDynamic(begins.size(), ResolveThreadCount(threads), 1, [&](std::size_t first, std::size_t last) {
    for (std::size_t b = first; b < last; ++b) {
      const std::size_t end = b + 1 < begins.size() ? begins[b + 1] : count_;
      blocks_[b] = std::make_unique<Block>(positions.subspan(3 * begins[b], 3 * (end - begins[b])));
    }
  });
}

NeighbourRadii::~NeighbourRadii() = default;

double NeighbourRadii::Radius(const double* query, int k, std::size_t first_block, double bound) const {
  if (k < 1) throw Error::InvalidArgument("NeighbourRadii: k must be at least 1, not " + std::to_string(k));
  if (first_block >= std::max<std::size_t>(blocks_.size(), 1)) {
    throw Error::InvalidArgument("NeighbourRadii: block " + std::to_string(first_block) + " of " +
                                 std::to_string(blocks_.size()));
  }
  if (count_ < static_cast<std::size_t>(k)) return std::numeric_limits<double>::infinity();
  thread_local std::vector<double> squared;
  squared.resize(static_cast<std::size_t>(k));
  const auto search = [&](double squared_bound) {
    BoundedKnnSet result(squared.data(), static_cast<std::size_t>(k), squared_bound);
    // The result set keeps the k nearest over every block searched. After the
    // first block the k-th distance is small; a block whose box lies farther
    // cannot improve it.
    blocks_[first_block]->index.findNeighbors(result, query, nanoflann::SearchParams());
    for (std::size_t b = 0; b < blocks_.size(); ++b) {
      if (b == first_block || blocks_[b]->SquaredDistance(query) > result.worstDist()) continue;
      blocks_[b]->index.findNeighbors(result, query, nanoflann::SearchParams());
    }
    return result.full();
  };
  // Widened a little so that rounding in the caller's sum cannot put the
  // k-th neighbour just outside.
  const double squared_bound = bound * bound * (1 + 1e-9);
  if (!(std::isfinite(squared_bound) && search(squared_bound))) search(std::numeric_limits<double>::infinity());
  return std::sqrt(squared[static_cast<std::size_t>(k) - 1]);
}

}  // namespace octocosm
