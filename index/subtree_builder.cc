#include "index/subtree_builder.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <map>
#include <string>
#include <utility>

#include "storage/error.h"

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

void CheckParticles(const ParticleChunk& particles, NodeKey region, const Cube& cube) {
  const std::size_t n = particles.size();
  bool lengths_agree = particles.position.size() == 3 * n && particles.type.size() == n &&
                       (!particles.has_id() || particles.id.size() == n);
  for (const std::vector<float>* column : VectorColumns(particles)) {
    lengths_agree &= column->empty() || column->size() == 3 * n;
  }
  if (!lengths_agree) {
    throw Error::InvalidArgument("subtree builder: particle columns of region " + region.Path() +
                                 " have inconsistent lengths for " + std::to_string(n) + " particles");
  }
  for (std::size_t i = 0; i < n; ++i) {
    const double* p = &particles.position[3 * i];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      throw Error::InvalidArgument("subtree builder: particle " + std::to_string(i) + " of region " + region.Path() +
                                   " has a non-finite position");
    }
    if (!cube.Holds(region, p)) {
      throw Error::InvalidArgument("subtree builder: particle " + std::to_string(i) + " at (" + std::to_string(p[0]) +
                                   ", " + std::to_string(p[1]) + ", " + std::to_string(p[2]) +
                                   ") lies outside region " + region.Path());
    }
    if (!(particles.mass[i] > 0) || !std::isfinite(particles.mass[i])) {
      throw Error::InvalidArgument("subtree builder: particle " + std::to_string(i) + " of region " + region.Path() +
                                   " has mass " + std::to_string(particles.mass[i]) + ", must be finite and > 0");
    }
  }
}

// The vector columns a set of points carries, one bit per VectorColumn.
template <typename Points>
unsigned PresentVectorColumns(const Points& points) {
  unsigned present = 0;
  const auto columns = VectorColumns(points);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) present |= columns[v]->empty() ? 0u : 1u << v;
  return present;
}

// Reserves room for `n` points in the vector columns of `to` that `like` carries.
template <typename Like>
void ReserveVectors(const Like& like, std::size_t n, NodePoints& to) {
  const auto source = VectorColumns(like);
  const auto target = VectorColumns(to);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (!source[v]->empty()) target[v]->reserve(3 * n);
  }
}

// Appends point `i` of `from`'s vector columns to the same columns of `to`
// (those `from` carries).
template <typename From, typename To>
void AppendVectors(const From& from, std::size_t i, To& to) {
  const auto source = VectorColumns(from);
  const auto target = VectorColumns(to);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (!source[v]->empty()) target[v]->insert(target[v]->end(), &(*source[v])[3 * i], &(*source[v])[3 * i] + 3);
  }
}

void SwapParticles(ParticleChunk& c, std::size_t i, std::size_t j) {
  for (int a = 0; a < 3; ++a) std::swap(c.position[3 * i + a], c.position[3 * j + a]);
  std::swap(c.mass[i], c.mass[j]);
  std::swap(c.type[i], c.type[j]);
  if (c.has_id()) std::swap(c.id[i], c.id[j]);
  for (std::vector<float>* column : VectorColumns(c)) {
    if (column->empty()) continue;
    for (int a = 0; a < 3; ++a) std::swap((*column)[3 * i + a], (*column)[3 * j + a]);
  }
}

// Groups particles [begin, end) by their child octant at `level`, in place
// (American flag sort: each particle is swapped straight into its octant's
// next free slot). Returns the absolute boundaries of the eight groups.
std::array<std::size_t, 9> PartitionByOctant(ParticleChunk& c, std::size_t begin, std::size_t end, int level,
                                             const Cube& cube) {
  std::vector<std::uint8_t> octant(end - begin);
  std::array<std::size_t, 9> bounds{};
  for (std::size_t i = begin; i < end; ++i) {
    octant[i - begin] = static_cast<std::uint8_t>(cube.ChildOctant(&c.position[3 * i], level));
    ++bounds[octant[i - begin] + 1];
  }
  bounds[0] = begin;
  for (int o = 0; o < 8; ++o) bounds[o + 1] += bounds[o];
  std::array<std::size_t, 9> next = bounds;
  for (int o = 0; o < 8; ++o) {
    while (next[o] < bounds[o + 1]) {
      const std::size_t i = next[o];
      const int target = octant[i - begin];
      if (target == o) {
        ++next[o];
        continue;
      }
      const std::size_t j = next[target]++;
      SwapParticles(c, i, j);
      std::swap(octant[i - begin], octant[j - begin]);
    }
  }
  return bounds;
}

NodePoints MakeLeaf(ParticleChunk& c, std::size_t begin, std::size_t end, NodeKey key, const Cube& cube,
                    const SubtreeOptions& options) {
  const auto bounds = PartitionByOctant(c, begin, end, key.level(), cube);
  // The in-place partition is not stable, so the order it leaves depends on
  // what else shared the array (a whole input or one chunk of it). Ordering
  // each octant's points by sampling ID (then by position, for inputs with
  // coincident points and no IDs) makes every node, and every floating-point
  // sum over a node, the same however the input was chunked.
  std::vector<std::size_t> order(end - begin);
  std::vector<std::uint64_t> sampling_id(end - begin);
  for (std::size_t i = begin; i < end; ++i) {
    order[i - begin] = i;
    sampling_id[i - begin] = c.has_id() ? c.id[i] : SamplingId(&c.position[3 * i]);
  }
  for (int o = 0; o < 8; ++o) {
    std::sort(order.begin() + static_cast<std::ptrdiff_t>(bounds[o] - begin),
              order.begin() + static_cast<std::ptrdiff_t>(bounds[o + 1] - begin), [&](std::size_t a, std::size_t b) {
                if (sampling_id[a - begin] != sampling_id[b - begin]) return sampling_id[a - begin] < sampling_id[b - begin];
                return std::lexicographical_compare(&c.position[3 * a], &c.position[3 * a + 3], &c.position[3 * b],
                                                    &c.position[3 * b + 3]);
              });
  }
  const std::size_t n = end - begin;
  NodePoints leaf;
  leaf.position.resize(3 * n);
  leaf.weight.resize(n);
  leaf.type.resize(n);
  if (c.has_id()) leaf.id.resize(n);
  ReserveVectors(c, n, leaf);
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t i = order[k];
    for (int a = 0; a < 3; ++a) leaf.position[3 * k + a] = c.position[3 * i + a];
    leaf.weight[k] = c.mass[i];
    leaf.type[k] = c.type[i];
    if (c.has_id()) leaf.id[k] = c.id[i];
    AppendVectors(c, i, leaf);
  }
  for (int o = 0; o < 9; ++o) leaf.octant_offsets[o] = static_cast<std::uint32_t>(bounds[o] - begin);
  leaf.smoothing = LeafSmoothingLengths(leaf.position, leaf.weight, key, cube, options.sampler);
  return leaf;
}

// The node `key` sampled from its children's points (children[o] is the
// child in octant o, possibly empty).
NodePoints SampleParent(NodeKey key, const std::array<NodePoints, 8>& children, const Cube& cube,
                        const SubtreeOptions& options) {
  std::size_t total = 0;
  int first = -1;
  for (int o = 0; o < 8; ++o) {
    if (children[o].size() == 0) continue;
    total += children[o].size();
    if (first < 0) first = o;
    const NodePoints& a = children[first];
    const NodePoints& b = children[o];
    if (a.id.empty() != b.id.empty() || PresentVectorColumns(a) != PresentVectorColumns(b)) {
      throw Error::InvalidArgument("subtree builder: children of node " + key.Path() +
                                   " disagree on which columns their points carry");
    }
  }
  const bool has_id = first >= 0 && !children[first].id.empty();

  // The sampler needs only positions, weights and sampling IDs; the other
  // columns are copied straight from the children for the kept points.
  std::vector<double> position, weight;
  std::vector<std::uint64_t> sampling_id;
  position.reserve(3 * total);
  weight.reserve(total);
  sampling_id.reserve(total);
  std::array<std::size_t, 9> child_begin{};
  for (int o = 0; o < 8; ++o) {
    const NodePoints& child = children[o];
    child_begin[o] = weight.size();
    position.insert(position.end(), child.position.begin(), child.position.end());
    weight.insert(weight.end(), child.weight.begin(), child.weight.end());
    if (has_id) {
      sampling_id.insert(sampling_id.end(), child.id.begin(), child.id.end());
    } else {
      for (std::size_t i = 0; i < child.size(); ++i) sampling_id.push_back(SamplingId(&child.position[3 * i]));
    }
  }
  child_begin[8] = weight.size();

  const Sample sample = SampleNode(position, weight, sampling_id, key, cube, options.capacity, options.sampler);
  NodePoints node;
  const std::size_t kept = sample.kept.size();
  node.position.reserve(3 * kept);
  node.type.reserve(kept);
  if (first >= 0) ReserveVectors(children[first], kept, node);
  node.weight = sample.weight;
  node.smoothing = sample.smoothing;
  int octant = 0;
  for (std::size_t j = 0; j < kept; ++j) {
    // Kept indices ascend and the population is grouped by octant, so the
    // node's points stay grouped by octant too.
    const std::uint32_t i = sample.kept[j];
    while (i >= child_begin[octant + 1]) node.octant_offsets[++octant] = static_cast<std::uint32_t>(j);
    const NodePoints& child = children[octant];
    const std::size_t k = i - child_begin[octant];
    for (int a = 0; a < 3; ++a) node.position.push_back(child.position[3 * k + a]);
    node.type.push_back(child.type[k]);
    if (has_id) node.id.push_back(child.id[k]);
    AppendVectors(child, k, node);
  }
  while (octant < 8) node.octant_offsets[++octant] = static_cast<std::uint32_t>(kept);
  return node;
}

NodePoints BuildNode(ParticleChunk& c, std::size_t begin, std::size_t end, NodeKey key, const Cube& cube,
                     const SubtreeOptions& options, const NodeSink& sink) {
  NodePoints node;
  if (end - begin <= options.capacity || key.level() >= options.max_level) {
    node = MakeLeaf(c, begin, end, key, cube, options);
  } else {
    const auto bounds = PartitionByOctant(c, begin, end, key.level(), cube);
    std::array<NodePoints, 8> children;
    for (int o = 0; o < 8; ++o) {
      if (bounds[o] < bounds[o + 1]) {
        children[o] = BuildNode(c, bounds[o], bounds[o + 1], key.Child(o), cube, options, sink);
      }
    }
    node = SampleParent(key, children, cube, options);
  }
  sink(key, NodePoints(node));
  return node;
}

}  // namespace

NodePoints BuildSubtree(ParticleChunk& particles, NodeKey region, const Cube& cube, const SubtreeOptions& options,
                        const NodeSink& sink) {
  cube.Validate();
  CheckOptions(options, region);
  CheckParticles(particles, region, cube);
  if (particles.size() == 0) return {};
  return BuildNode(particles, 0, particles.size(), region, cube, options, sink);
}

TopLevelMerger::TopLevelMerger(const Cube& cube, const SubtreeOptions& options, NodeSink sink)
    : cube_(cube), options_(options), sink_(std::move(sink)) {
  cube_.Validate();
}

void TopLevelMerger::CloseDeepest() {
  Open closing = std::move(open_.back());
  open_.pop_back();
  NodePoints node = SampleParent(closing.key, closing.children, cube_, options_);
  sink_(closing.key, NodePoints(node));
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
