#include "index/subtree_builder.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <map>
#include <span>
#include <string>
#include <utility>

#include "index/aggregator.h"
#include "index/cluster_shape.h"
#include "index/block_codec.h"
#include "index/radix_sort.h"
#include "base/error.h"

namespace octocosm {
namespace {

void CheckOptions(const SubtreeOptions& options, NodeKey region) {
  if (options.capacity == 0) throw Error::InvalidArgument("subtree builder: capacity must be at least 1");
  if (options.max_level < 0 || options.max_level > kMaxLevel) {
    throw Error::InvalidArgument("subtree builder: max_level " + std::to_string(options.max_level) +
                                 " must be in 0.." + std::to_string(kMaxLevel));
  }
  if (!region.IsValid() || region.level() > options.max_level) {
    throw Error::InvalidArgument("subtree builder: region key " + std::to_string(region.value()) +
                                 " is not a valid node at or above max_level " + std::to_string(options.max_level));
  }
}

using Placed = PlacedParticle;

// Checks the particles and places them into `placed`.
void PlaceParticles(const ParticleChunk& particles, NodeKey region, const Cube& cube, std::vector<Placed>& placed) {
  const std::size_t n = particles.size();
  bool lengths_agree = particles.position.size() == 3 * n && particles.type.size() == n &&
                       (!particles.has_id() || particles.id.size() == n) &&
                       (!particles.has_smoothing() || particles.smoothing.size() == n);
  for (const std::vector<float>* column : VectorColumns(particles)) {
    lengths_agree &= column->empty() || column->size() == 3 * n;
  }
  if (!lengths_agree) {
    throw Error::InvalidArgument("subtree builder: particle columns of region " + region.Path() +
                                 " have inconsistent lengths for " + std::to_string(n) + " particles");
  }
  if (n > std::numeric_limits<std::uint32_t>::max()) {
    throw Error::InvalidArgument("subtree builder: region " + region.Path() + " has " + std::to_string(n) +
                                 " particles, more than one build takes (2^32 - 1)");
  }
  placed.clear();
  placed.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double* p = &particles.position[3 * i];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      throw Error::InvalidArgument("subtree builder: particle " + std::to_string(i) + " of region " + region.Path() +
                                   " has a non-finite position");
    }
    placed.push_back({cube.FinestGridCoords(p), static_cast<std::uint32_t>(i)});
    if (!GridHolds(placed[i].grid, region)) {
      throw Error::InvalidArgument("subtree builder: particle " + std::to_string(i) + " at (" + std::to_string(p[0]) +
                                   ", " + std::to_string(p[1]) + ", " + std::to_string(p[2]) +
                                   ") lies outside region " + region.Path());
    }
    if (!(particles.mass[i] > 0) || !std::isfinite(particles.mass[i])) {
      throw Error::InvalidArgument("subtree builder: particle " + std::to_string(i) + " of region " + region.Path() +
                                   " has mass " + std::to_string(particles.mass[i]) + ", must be finite and > 0");
    }
  }
  for (std::size_t i = 0; i < particles.smoothing.size(); ++i) {
    const float h = particles.smoothing[i];
    if (!(h >= 0) || !std::isfinite(h)) {
      throw Error::InvalidArgument("subtree builder: particle " + std::to_string(i) + " of region " + region.Path() +
                                   " has smoothing length " + std::to_string(h) + ", must be finite and >= 0");
    }
  }
}

// The smoothing lengths of a leaf whose particles carry given ones
// (`given`, in the leaf's order): each given length where it is > 0, held
// to the range a block stores (GivenSmoothingRange), and the density-grid
// rule's for the others, computed only when there are any.
std::vector<double> LeafSmoothingWithGiven(const NodePoints& leaf, const std::vector<float>& given, NodeKey key,
                                           const Cube& cube, const SamplerOptions& options) {
  const bool all_given = std::all_of(given.begin(), given.end(), [](float h) { return h > 0; });
  std::vector<double> h = all_given ? std::vector<double>(given.size())
                                    : LeafSmoothingLengths(leaf.grid, leaf.weight, key, cube, options);
  const auto [lo, hi] = GivenSmoothingRange(cube.NodeSize(key.level()));
  for (std::size_t k = 0; k < given.size(); ++k) {
    if (given[k] > 0) h[k] = std::clamp<double>(given[k], lo, hi);
  }
  return h;
}

// The vector columns a set of points carries, one bit per VectorColumn.
template <typename Points>
unsigned PresentVectorColumns(const Points& points) {
  unsigned present = 0;
  const auto columns = VectorColumns(points);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) present |= columns[v]->empty() ? 0u : 1u << v;
  return present;
}

// Groups [begin, end) by the child octant at `level` that holds each point,
// in place (American flag sort: each record is swapped straight into its
// octant's next free slot). Returns the offsets of the eight groups from
// `begin`. `octant` is scratch.
std::array<std::size_t, 9> PartitionByOctant(Placed* begin, Placed* end, int level, std::vector<std::uint8_t>& octant) {
  const std::size_t n = static_cast<std::size_t>(end - begin);
  octant.resize(n);
  std::array<std::size_t, 9> bounds{};
  for (std::size_t i = 0; i < n; ++i) {
    octant[i] = static_cast<std::uint8_t>(OctantAt(begin[i].grid, level));
    ++bounds[octant[i] + 1];
  }
  for (int o = 0; o < 8; ++o) bounds[o + 1] += bounds[o];
  std::array<std::size_t, 9> next = bounds;
  for (int o = 0; o < 8; ++o) {
    while (next[o] < bounds[o + 1]) {
      const std::size_t i = next[o];
      const int target = octant[i];
      if (target == o) {
        ++next[o];
        continue;
      }
      const std::size_t j = next[target]++;
      std::swap(begin[i], begin[j]);
      std::swap(octant[i], octant[j]);
    }
  }
  return bounds;
}

// Appends the sampling IDs of a node's points to `ids`: particle IDs, or for
// inputs without them a hash of the position.
void AppendSamplingIds(const NodePoints& node, std::vector<std::uint64_t>& ids) {
  if (!node.id.empty()) {
    ids.insert(ids.end(), node.id.begin(), node.id.end());
    return;
  }
  for (std::size_t i = 0; i < node.size(); ++i) ids.push_back(SamplingId(&node.position[3 * i]));
}

// Appends the node's grid points to `grid`: its own, or for points that came
// without them (a caller's NodePoints), computed.
void AppendGridPoints(const NodePoints& node, const Cube& cube, std::vector<GridPoint>& grid) {
  if (node.grid.size() == node.size()) {
    grid.insert(grid.end(), node.grid.begin(), node.grid.end());
    return;
  }
  for (std::size_t i = 0; i < node.size(); ++i) grid.push_back(cube.FinestGridCoords(&node.position[3 * i]));
}

// The first non-empty child of `key` (-1 when all are empty), after checking
// that every non-empty child's points carry the same optional columns. The
// velocity dispersion is the exception: clusters carry it and single
// particles (leaves) or samples do not, so siblings may differ; where
// present it must go with velocities and have one value per point.
int FirstChildAgreeingOnColumns(NodeKey key, const std::array<NodePoints, 8>& children) {
  int first = -1;
  for (int o = 0; o < 8; ++o) {
    if (children[o].size() == 0) continue;
    if (first < 0) first = o;
    const NodePoints& a = children[first];
    const NodePoints& b = children[o];
    if (a.id.empty() != b.id.empty() || PresentVectorColumns(a) != PresentVectorColumns(b)) {
      throw Error::InvalidArgument("subtree builder: children of node " + key.Path() +
                                   " disagree on which columns their points carry");
    }
    if (!b.velocity_dispersion.empty() && (b.velocity_dispersion.size() != b.size() || b.velocity.empty())) {
      throw Error::InvalidArgument("subtree builder: child " + key.Child(o).Path() + " has " +
                                   std::to_string(b.velocity_dispersion.size()) + " velocity dispersions for " +
                                   std::to_string(b.size()) + " points" +
                                   (b.velocity.empty() ? " and no velocities" : ""));
    }
    if (!b.shape.empty() && b.shape.size() != 6 * b.size()) {
      throw Error::InvalidArgument("subtree builder: child " + key.Child(o).Path() + " has " +
                                   std::to_string(b.shape.size()) + " shape codes for " + std::to_string(b.size()) +
                                   " points");
    }
  }
  return first;
}

// The node `key` sampled from its children's points (children[o] is the
// child in octant o, possibly empty).
NodePoints SampleParent(NodeKey key, const std::array<NodePoints, 8>& children, const Cube& cube,
                        const SubtreeOptions& options) {
  std::size_t total = 0;
  for (const NodePoints& child : children) total += child.size();
  const int first = FirstChildAgreeingOnColumns(key, children);
  const bool has_id = first >= 0 && !children[first].id.empty();

  // The sampler needs only grid points, weights and sampling IDs; the other
  // columns are copied straight from the children for the kept points.
  std::vector<GridPoint> grid;
  std::vector<double> weight;
  std::vector<std::uint64_t> sampling_id;
  grid.reserve(total);
  weight.reserve(total);
  sampling_id.reserve(total);
  std::array<std::size_t, 9> child_begin{};
  for (int o = 0; o < 8; ++o) {
    const NodePoints& child = children[o];
    child_begin[o] = weight.size();
    if (child.size() == 0) continue;
    AppendGridPoints(child, cube, grid);
    weight.insert(weight.end(), child.weight.begin(), child.weight.end());
    AppendSamplingIds(child, sampling_id);
  }
  child_begin[8] = weight.size();

  Sample sample = SampleNode(grid, weight, sampling_id, key, cube, options.capacity, options.sampler);
  NodePoints node;
  const std::size_t kept = sample.kept.size();
  node.weight = std::move(sample.weight);
  node.smoothing = std::move(sample.smoothing);
  // Sized first and written through pointers: push_back of a byte (the type)
  // may alias every vector's pointers, which were then loaded again for
  // every value.
  node.position.resize(3 * kept);
  node.type.resize(kept);
  node.grid.resize(kept);
  if (has_id) node.id.resize(kept);
  std::array<float*, kVectorColumnCount> vectors_to{};
  std::array<std::array<const float*, kVectorColumnCount>, 8> vectors_from{};
  if (first >= 0) {
    const auto like = VectorColumns(children[first]);
    const auto target = VectorColumns(node);
    for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
      if (like[v]->empty()) continue;
      target[v]->resize(3 * kept);
      vectors_to[v] = target[v]->data();
      for (int o = 0; o < 8; ++o) vectors_from[o][v] = VectorColumns(children[o])[v]->data();
    }
  }
  double* position = node.position.data();
  std::uint8_t* type = node.type.data();
  GridPoint* kept_grid = node.grid.data();
  std::uint64_t* id = node.id.data();
  int octant = 0;
  for (std::size_t j = 0; j < kept; ++j) {
    // Kept indices ascend and the population is grouped by octant, so the
    // node's points stay grouped by octant too.
    const std::uint32_t i = sample.kept[j];
    while (i >= child_begin[octant + 1]) node.octant_offsets[++octant] = static_cast<std::uint32_t>(j);
    const NodePoints& child = children[octant];
    const std::size_t k = i - child_begin[octant];
    // Element by element: GCC 12 made each std::copy_n of three values a
    // call to memmove (2 % of a 10^8-point ingest).
    const double* from = &child.position[3 * k];
    for (int a = 0; a < 3; ++a) position[3 * j + a] = from[a];
    type[j] = child.type[k];
    kept_grid[j] = grid[i];
    if (has_id) id[j] = child.id[k];
    for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
      if (vectors_to[v] == nullptr) continue;
      const float* vector_from = vectors_from[octant][v] + 3 * k;
      for (int a = 0; a < 3; ++a) vectors_to[v][3 * j + a] = vector_from[a];
    }
  }
  while (octant < 8) node.octant_offsets[++octant] = static_cast<std::uint32_t>(kept);
  return node;
}

// A cluster's moments (AggregateParent): its mass, centre of mass,
// mass-weighted mean vectors, spread, covariance and velocity variance, and
// its heaviest member, from the members' population indices.
struct ClusterMoments {
  double mass = 0;
  double centre[3] = {0, 0, 0};
  std::array<std::array<double, 3>, kVectorColumnCount> vector_mean{};
  double variance = 0;           // mass-weighted, per axis, times the mass
  double velocity_variance = 0;  // mass-weighted, three-dimensional, times the mass
  SymmetricMatrix covariance{};  // times the mass
  std::uint32_t heaviest = 0;
};

ClusterMoments MeasureCluster(std::span<const std::uint32_t> members,
                              std::span<const std::pair<std::uint8_t, std::uint32_t>> from,
                              const std::array<NodePoints, 8>& children, std::span<const double> weight,
                              const std::array<bool, kVectorColumnCount>& has_vector, bool has_dispersion) {
  const std::size_t velocity = static_cast<std::size_t>(VectorColumn::kVelocity);
  double mass = 0, centre[3] = {0, 0, 0};
  std::array<std::array<double, 3>, kVectorColumnCount> vector_mean{};
  std::uint32_t heaviest = members.front();
  for (const std::uint32_t m : members) {
    const auto [o, k] = from[m];
    const NodePoints& child = children[o];
    const double w = child.weight[k];
    mass += w;
    for (int a = 0; a < 3; ++a) centre[a] += w * child.position[3 * k + a];
    for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
      if (!has_vector[v]) continue;
      const float* value = &(*VectorColumns(child)[v])[3 * k];
      for (int a = 0; a < 3; ++a) vector_mean[v][a] += w * value[a];
    }
    if (w > weight[heaviest]) heaviest = m;
  }
  // mass > 0: every weight is > 0 (ClusterPopulation's contract).
  for (double& x : centre) x /= mass;
  for (auto& mean : vector_mean) {
    for (double& x : mean) x /= mass;
  }
  // The spread: each member's squared distance from the centre, a third per
  // axis, and its own blob's variance, mass-weighted. The velocity
  // dispersion likewise: each member's squared offset from the mean
  // velocity and its own three-dimensional variance 3 sigma^2 (the
  // parallel-axis rule, so a cluster of clusters has the dispersion of all
  // the particles below it).
  // The covariance likewise, entry by entry (index/cluster_shape.h): the
  // offsets' outer products and each member's own blob, of its shape.
  double variance = 0, velocity_variance = 0;
  SymmetricMatrix covariance{};
  for (const std::uint32_t m : members) {
    const auto [o, k] = from[m];
    const NodePoints& child = children[o];
    const double w = child.weight[k];
    double d[3], d2 = 0;
    for (int a = 0; a < 3; ++a) {
      d[a] = child.position[3 * k + a] - centre[a];
      d2 += d[a] * d[a];
    }
    const double own = KernelVariance(child.smoothing[k]);
    variance += w * (d2 / 3 + own);
    const SymmetricMatrix shape = child.shape.empty() ? kRoundShape : DecodeShape(ShapeCodeAt(child.shape, k));
    const double outer[6] = {d[0] * d[0], d[1] * d[1], d[2] * d[2], d[0] * d[1], d[0] * d[2], d[1] * d[2]};
    for (int i = 0; i < 6; ++i) covariance[i] += w * (outer[i] + own * shape[i]);
    if (has_dispersion) {
      const float* value = &child.velocity[3 * k];
      double dv2 = 0;
      for (int a = 0; a < 3; ++a) {
        const double dv = value[a] - vector_mean[velocity][a];
        dv2 += dv * dv;
      }
      const double own_sigma = child.velocity_dispersion.empty() ? 0.0 : double{child.velocity_dispersion[k]};
      velocity_variance += w * (dv2 + 3 * own_sigma * own_sigma);
    }
  }
  ClusterMoments moments;
  moments.mass = mass;
  for (int a = 0; a < 3; ++a) moments.centre[a] = centre[a];
  moments.vector_mean = vector_mean;
  moments.variance = variance;
  moments.velocity_variance = velocity_variance;
  moments.covariance = covariance;
  moments.heaviest = heaviest;
  return moments;
}

// Positions as a block of level `level` decodes them (index/block_codec.h):
// the centre of their quantum, to within rounding.
class PositionDecoder {
 public:
  PositionDecoder(const Cube& cube, int level) : bits_(level + 16), quantum_(std::ldexp(cube.size, -bits_)) {
    for (int a = 0; a < 3; ++a) corner_[a] = cube.origin[a] + 0.5 * quantum_;
  }
  std::array<double, 3> operator()(const GridPoint& grid) const {
    std::array<double, 3> x{};
    for (int a = 0; a < 3; ++a) x[a] = static_cast<double>(GridAxisAt(grid, a, bits_)) * quantum_ + corner_[a];
    return x;
  }
  // The largest difference between two decodings of one position (the
  // block codec's rounding and this one's), with room to spare.
  double slack() const { return 2 * quantum_; }

 private:
  int bits_;
  double quantum_;
  double corner_[3];
};

// `x` rounded up to a float (the largest finite float at most), so that a
// bound stays a bound once stored.
float FloatAtLeast(double x) {
  if (!(x < double{std::numeric_limits<float>::max()})) return std::numeric_limits<float>::max();
  float f = static_cast<float>(x);
  if (double{f} < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

// A parent's refine bounds exceed its clusters' by this much at least, so
// that a renderer's float arithmetic, deciding for the parent and for each
// cluster below it apart, never finds a cluster costlier than its parent.
constexpr double kRefineBoundMargin = 1.0 / 4096;

// The cluster `members` of node `key` (decoded position `centre`, mass,
// smoothing length h as stored) as the refine_bound column holds it: R, a, r
// (index/block_codec.h). Members of children without bounds (leaves) are
// particles: their spheres are points, and they are never refined.
std::array<float, 3> RefineBound(std::span<const std::uint32_t> members,
                                 std::span<const std::pair<std::uint8_t, std::uint32_t>> from,
                                 std::span<const GridPoint> grid, const std::array<NodePoints, 8>& children,
                                 const Cube& cube, NodeKey key, const std::array<double, 3>& centre, double mass,
                                 double h) {
  double radius = 0, error = mass * KernelVariance(h), cap = mass;
  const PositionDecoder member_position(cube, key.level() + 1);
  for (const std::uint32_t m : members) {
    const auto [o, k] = from[m];
    const std::array<double, 3> x = member_position(grid[m]);
    const double d = std::sqrt((x[0] - centre[0]) * (x[0] - centre[0]) + (x[1] - centre[1]) * (x[1] - centre[1]) +
                               (x[2] - centre[2]) * (x[2] - centre[2]));
    const std::vector<float>& bound = children[o].refine_bound;
    if (bound.empty()) {
      radius = std::max(radius, d);
      continue;
    }
    radius = std::max(radius, d + double{bound[3 * k]});
    error = std::max(error, double{bound[3 * k + 1]});
    cap = std::max(cap, double{bound[3 * k + 2]});
  }
  // The renderer decodes positions with its own rounding.
  return {FloatAtLeast(radius * (1 + kRefineBoundMargin) + member_position.slack()), FloatAtLeast(error * (1 + kRefineBoundMargin)),
          FloatAtLeast(cap * (1 + kRefineBoundMargin))};
}

// The node `key` as clusters of its children's points (index/aggregator.h):
// each cluster's mass, centre of mass and spread in one point, and with
// velocities its mass-weighted mean velocity and velocity dispersion.
// Children's columns must agree as for SampleParent.
NodePoints AggregateParent(NodeKey key, const std::array<NodePoints, 8>& children, const Cube& cube,
                           const SubtreeOptions& options) {
  const int first = FirstChildAgreeingOnColumns(key, children);
  // The population: every child's points, child by child, and where each
  // came from.
  std::vector<GridPoint> grid;
  std::vector<double> weight;
  std::vector<double> own_variance;  // each point's own blob, per axis, in node edges squared
  std::vector<std::uint8_t> types;
  std::vector<std::pair<std::uint8_t, std::uint32_t>> from;  // (child octant, index in it)
  std::array<bool, 256> present{};
  const double edge = cube.NodeSize(key.level());
  for (int o = 0; o < 8; ++o) {
    const NodePoints& child = children[o];
    if (child.size() == 0) continue;
    AppendGridPoints(child, cube, grid);
    weight.insert(weight.end(), child.weight.begin(), child.weight.end());
    for (const double h : child.smoothing) own_variance.push_back(KernelVariance(h / edge));
    types.insert(types.end(), child.type.begin(), child.type.end());
    for (std::size_t k = 0; k < child.size(); ++k) from.emplace_back(static_cast<std::uint8_t>(o), static_cast<std::uint32_t>(k));
  }
  for (const std::uint8_t t : types) present[t] = true;
  if (options.capacity < 8 * static_cast<std::size_t>(std::max<std::ptrdiff_t>(1, std::count(present.begin(), present.end(), true)))) {
    return SampleParent(key, children, cube, options);  // too few points for a cluster per octant and type
  }
  const Clusters clusters = ClusterPopulation(grid, weight, own_variance, types, key, options.capacity);
  const std::size_t n = clusters.size();
  NodePoints node;
  node.position.resize(3 * n);
  node.weight.resize(n);
  node.smoothing.resize(n);
  node.type.resize(n);
  node.grid.resize(n);
  node.shape.resize(6 * n);
  node.child_cluster.resize(grid.size());
  node.refine_bound.resize(3 * n);
  const bool has_id = first >= 0 && !children[first].id.empty();
  if (has_id) node.id.resize(n);
  std::array<bool, kVectorColumnCount> has_vector{};
  if (first >= 0) {
    const auto like = VectorColumns(children[first]);
    const auto target = VectorColumns(node);
    for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
      has_vector[v] = !like[v]->empty();
      if (has_vector[v]) target[v]->resize(3 * n);
    }
  }
  // A cluster of particles with velocities keeps how their velocities
  // spread about its mean: clusters that are one particle each carry 0.
  const std::size_t velocity = static_cast<std::size_t>(VectorColumn::kVelocity);
  const bool has_dispersion = has_vector[velocity];
  if (has_dispersion) node.velocity_dispersion.resize(n);
  const auto node_vectors = VectorColumns(node);
  const auto [min_h, max_h] = GivenSmoothingRange(cube.NodeSize(key.level()));
  int octant = 0;
  for (std::size_t c = 0; c < n; ++c) {
    const std::uint32_t* begin = clusters.member.data() + clusters.begin[c];
    const std::uint32_t* end = clusters.member.data() + clusters.begin[c + 1];
    const ClusterMoments moments = MeasureCluster({begin, end}, from, children, weight, has_vector, has_dispersion);
    const std::uint32_t heaviest = moments.heaviest;
    const double mass = moments.mass;
    double centre[3] = {moments.centre[0], moments.centre[1], moments.centre[2]};
    const auto& vector_mean = moments.vector_mean;
    const double variance = moments.variance, velocity_variance = moments.velocity_variance;
    const SymmetricMatrix& covariance = moments.covariance;
    const auto [ho, hk] = from[heaviest];
    // The centre of mass lies in the cluster's cell, so in the child octant
    // of its members; should rounding put it on the far side of a face, the
    // heaviest member's place stands in.
    GridPoint centre_grid = cube.FinestGridCoords(centre);
    if (!GridHolds(centre_grid, key) || OctantAt(centre_grid, key.level()) != ho) {
      for (int a = 0; a < 3; ++a) centre[a] = children[ho].position[3 * hk + a];
      centre_grid = grid[heaviest];
    }
    while (ho > octant) node.octant_offsets[++octant] = static_cast<std::uint32_t>(c);
    for (int a = 0; a < 3; ++a) node.position[3 * c + a] = centre[a];
    node.grid[c] = centre_grid;
    node.weight[c] = mass;
    node.smoothing[c] = std::clamp(KernelRadiusForVariance(variance / mass), min_h, max_h);
    const std::array<std::uint8_t, 6> shape = EncodeShape(covariance);
    std::copy(shape.begin(), shape.end(), node.shape.begin() + static_cast<std::ptrdiff_t>(6 * c));
    node.type[c] = children[ho].type[hk];
    if (has_id) node.id[c] = children[ho].id[hk];
    for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
      if (!has_vector[v]) continue;
      for (int a = 0; a < 3; ++a) (*node_vectors[v])[3 * c + a] = static_cast<float>(vector_mean[v][a]);
    }
    if (has_dispersion) {
      // Held to the float range: members at +-FLT_MAX may spread by more.
      const double sigma = std::sqrt(velocity_variance / (3 * mass));
      node.velocity_dispersion[c] = static_cast<float>(std::min(sigma, double{std::numeric_limits<float>::max()}));
    }
    for (const std::uint32_t* m = begin; m != end; ++m) node.child_cluster[*m] = static_cast<std::uint32_t>(c);
    const std::array<float, 3> bound = RefineBound({begin, end}, from, grid, children, cube, key,
                                                   PositionDecoder(cube, key.level())(centre_grid), mass,
                                                   StoredSmoothing(node.smoothing[c], edge));
    std::copy(bound.begin(), bound.end(), node.refine_bound.begin() + static_cast<std::ptrdiff_t>(3 * c));
  }
  while (octant < 8) node.octant_offsets[++octant] = static_cast<std::uint32_t>(n);
  // As the block will hold them, so that the node above bounds these values.
  QuantizeRefineBounds(node.refine_bound);
  return node;
}

// Once a node is written, the node above needs its clusters but not which of
// its children's points each holds (4 bytes a child point, held along the
// path of open nodes otherwise).
void ReleaseChildClusters(NodePoints& node) { std::vector<std::uint32_t>().swap(node.child_cluster); }

// The node above `children`: clusters or a sample, as the options say.
NodePoints MakeParent(NodeKey key, const std::array<NodePoints, 8>& children, const Cube& cube,
                      const SubtreeOptions& options) {
  if (options.coarse == CoarsePoints::kClusters) return AggregateParent(key, children, cube, options);
  return SampleParent(key, children, cube, options);
}

// One BuildSubtree call: the particles, placed, and where nodes go.
class SubtreeBuild {
 public:
  SubtreeBuild(const ParticleChunk& particles, const Cube& cube, const SubtreeOptions& options, const NodeSink& sink,
               std::vector<std::uint8_t>& octant_scratch)
      : particles_(particles), cube_(cube), options_(options), sink_(sink), octant_scratch_(octant_scratch) {}

  // Builds the node `key` from the particles `placed` [begin, end), its
  // subtree first, and hands each node to the sink.
  NodePoints Build(Placed* begin, Placed* end, NodeKey key) {
    NodePoints node;
    if (static_cast<std::size_t>(end - begin) <= options_.capacity || key.level() >= options_.max_level) {
      node = MakeLeaf(begin, end, key);
    } else {
      const auto bounds = PartitionByOctant(begin, end, key.level(), octant_scratch_);
      std::array<NodePoints, 8> children;
      for (int o = 0; o < 8; ++o) {
        if (bounds[o] < bounds[o + 1]) children[o] = Build(begin + bounds[o], begin + bounds[o + 1], key.Child(o));
      }
      node = MakeParent(key, children, cube_, options_);
    }
    sink_(key, node);
    ReleaseChildClusters(node);
    return node;
  }

 private:
  NodePoints MakeLeaf(Placed* begin, Placed* end, NodeKey key) {
    const ParticleChunk& c = particles_;
    const auto bounds = PartitionByOctant(begin, end, key.level(), octant_scratch_);
    // The in-place partition is not stable, so the order it leaves depends on
    // what else shared the array (a whole input or one chunk of it). Ordering
    // each octant's points by sampling ID (then by position, for inputs with
    // coincident points and no IDs) makes every node, and every floating-point
    // sum over a node, the same however the input was chunked.
    const std::size_t n = static_cast<std::size_t>(end - begin);
    struct Keyed {
      std::uint64_t sampling_id;
      std::uint32_t index;  // into the particles
      std::uint32_t at;     // into [begin, end)
    };
    std::vector<Keyed> order(n);
    for (std::size_t k = 0; k < n; ++k) {
      const std::uint32_t i = begin[k].index;
      order[k] = {c.has_id() ? c.id[i] : SamplingId(&c.position[3 * std::size_t{i}]), i, static_cast<std::uint32_t>(k)};
    }
    // By radix on the ID, then by position within the rare runs of equal IDs.
    const auto by_position = [&c](const Keyed& a, const Keyed& b) {
      const double* pa = &c.position[3 * std::size_t{a.index}];
      const double* pb = &c.position[3 * std::size_t{b.index}];
      return std::lexicographical_compare(pa, pa + 3, pb, pb + 3);
    };
    std::vector<Keyed> scratch(n);
    for (int o = 0; o < 8; ++o) {
      const std::span<Keyed> octant(order.data() + bounds[o], bounds[o + 1] - bounds[o]);
      const std::span<Keyed> sorted =
          RadixSortByKey(octant, std::span<Keyed>(scratch.data(), octant.size()),
                         [](const Keyed& k) { return k.sampling_id; });
      if (sorted.data() != octant.data()) std::copy(sorted.begin(), sorted.end(), octant.begin());
      for (std::size_t run = 0; run < octant.size();) {
        std::size_t run_end = run + 1;
        while (run_end < octant.size() && octant[run_end].sampling_id == octant[run].sampling_id) ++run_end;
        if (run_end - run > 1) {
          std::sort(octant.begin() + static_cast<std::ptrdiff_t>(run), octant.begin() + static_cast<std::ptrdiff_t>(run_end),
                    by_position);
        }
        run = run_end;
      }
    }
    NodePoints leaf;
    leaf.position.resize(3 * n);
    leaf.weight.resize(n);
    leaf.type.resize(n);
    leaf.grid.resize(n);
    if (c.has_id()) leaf.id.resize(n);
    // Given smoothing lengths in the leaf's order; nothing without them.
    const float* given_from = c.has_smoothing() ? c.smoothing.data() : nullptr;
    std::vector<float> given_smoothing(given_from != nullptr ? n : 0);
    const auto source_vectors = VectorColumns(c);
    const auto leaf_vectors = VectorColumns(leaf);
    for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
      if (!source_vectors[v]->empty()) leaf_vectors[v]->resize(3 * n);
    }
    // Each point is read where it lies and written to its slot in the sorted
    // order: the chunk's columns come from memory in one forward sweep (a
    // gatherer lays a leaf's points out together), and the scattered writes
    // land in the leaf's columns, which are small enough to stay in cache.
    // Read in sorted order instead, nearly every read missed the cache.
    std::vector<std::uint32_t> slot(n);
    for (std::size_t k = 0; k < n; ++k) slot[order[k].at] = static_cast<std::uint32_t>(k);
    for (std::size_t m = 0; m < n; ++m) {
      const std::size_t i = begin[m].index;
      const std::size_t k = slot[m];
      for (int a = 0; a < 3; ++a) leaf.position[3 * k + a] = c.position[3 * i + a];
      leaf.weight[k] = c.mass[i];
      leaf.type[k] = c.type[i];
      leaf.grid[k] = begin[m].grid;
      if (c.has_id()) leaf.id[k] = c.id[i];
      if (given_from != nullptr) given_smoothing[k] = given_from[i];
      for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
        if (source_vectors[v]->empty()) continue;
        const float* from = &(*source_vectors[v])[3 * i];
        float* to = &(*leaf_vectors[v])[3 * k];
        to[0] = from[0];
        to[1] = from[1];
        to[2] = from[2];
      }
    }
    for (int o = 0; o < 9; ++o) leaf.octant_offsets[o] = static_cast<std::uint32_t>(bounds[o]);
    if (given_from != nullptr) {
      leaf.smoothing = LeafSmoothingWithGiven(leaf, given_smoothing, key, cube_, options_.sampler);
    } else {
      leaf.smoothing = LeafSmoothingLengths(leaf.grid, leaf.weight, key, cube_, options_.sampler);
    }
    return leaf;
  }

  const ParticleChunk& particles_;
  const Cube& cube_;
  const SubtreeOptions& options_;
  const NodeSink& sink_;
  std::vector<std::uint8_t>& octant_scratch_;
};

}  // namespace

std::pair<double, double> GivenSmoothingRange(double node_size) {
  return {node_size * std::exp2(double{kSmoothingLog2Min}),
          node_size * std::exp2(kSmoothingLog2Min + 65535.0 / kSmoothingPerOctave)};
}

NodePoints BuildSubtree(const ParticleChunk& particles, NodeKey region, const Cube& cube,
                        const SubtreeOptions& options, const NodeSink& sink, SubtreeWorkspace* workspace) {
  cube.Validate();
  CheckOptions(options, region);
  SubtreeWorkspace own;
  SubtreeWorkspace& work = workspace != nullptr ? *workspace : own;
  std::vector<Placed>& placed = work.placed;
  PlaceParticles(particles, region, cube, placed);
  if (placed.empty()) return {};
  SubtreeBuild build(particles, cube, options, sink, work.octant);
  return build.Build(placed.data(), placed.data() + placed.size(), region);
}

TopLevelMerger::TopLevelMerger(const Cube& cube, const SubtreeOptions& options, NodeSink sink)
    : cube_(cube), options_(options), sink_(std::move(sink)) {
  cube_.Validate();
}

void TopLevelMerger::CloseDeepest() {
  Open closing = std::move(open_.back());
  open_.pop_back();
  NodePoints node = MakeParent(closing.key, closing.children, cube_, options_);
  sink_(closing.key, node);
  ReleaseChildClusters(node);
  if (open_.empty()) {
    root_ = std::move(node);
  } else {
    open_.back().children[closing.key.OctantInParent()] = std::move(node);
  }
}

void TopLevelMerger::Add(NodeKey region, NodePoints points) {
  if (finished_) throw Error::InvalidArgument("TopLevelMerger: Add after Finish");
  CheckOptions(options_, region);
  if (have_last_ && !PreorderLess{}(last_, region)) {
    throw Error::InvalidArgument("TopLevelMerger: region " + region.Path() + " does not follow " + last_.Path() +
                                 " in depth-first order");
  }
  if (have_last_ && last_.IsAncestorOrSelf(region)) {
    throw Error::InvalidArgument("TopLevelMerger: region " + last_.Path() + " overlaps region " + region.Path());
  }
  have_last_ = true;
  last_ = region;
  if (points.size() == 0) return;
  if (region.level() == 0) {
    if (!open_.empty() || root_.size() > 0) throw Error::InvalidArgument("TopLevelMerger: the root overlaps other regions");
    root_ = std::move(points);
    return;
  }
  // Close what the new region is not inside of: those subtrees are complete.
  while (!open_.empty() && !open_.back().key.IsAncestorOrSelf(region)) CloseDeepest();
  const int depth = open_.empty() ? 0 : open_.back().key.level() + 1;
  for (int level = depth; level < region.level(); ++level) open_.push_back({region.AncestorAt(level), {}});
  open_.back().children[region.OctantInParent()] = std::move(points);
}

NodePoints TopLevelMerger::Finish() {
  if (!finished_) {
    finished_ = true;
    while (!open_.empty()) CloseDeepest();
  }
  return std::move(root_);
}

NodePoints BuildTopLevels(std::vector<RegionRoot> regions, const Cube& cube, const SubtreeOptions& options,
                          const NodeSink& sink) {
  std::sort(regions.begin(), regions.end(),
            [](const RegionRoot& a, const RegionRoot& b) { return PreorderLess{}(a.key, b.key); });
  TopLevelMerger merger(cube, options, sink);
  for (RegionRoot& r : regions) merger.Add(r.key, std::move(r.points));
  return merger.Finish();
}

}  // namespace octocosm
