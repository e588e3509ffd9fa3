// The promise of the cluster links (docs/FORMAT.md section 4): for any camera
// and threshold, drawing each point whose bound E is at most the threshold
// (a leaf's particles: always) and whose parent cluster's E is above it (or
// that has no parent) draws every particle's mass exactly once: a cut of the
// tree, each point deciding alone. E is evaluated in float from the blocks as
// a reader decodes them, as a renderer would.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <random>
#include <vector>

#include "index/block_codec.h"
#include "index/subtree_builder.h"

namespace octocosm {
namespace {

const Cube kCube{{-50, -50, -50}, 100, false};

// Clumps of several widths over a uniform background, two particle types.
ParticleChunk Clumps(std::mt19937_64& rng, std::size_t n) {
  ParticleChunk c;
  std::uniform_real_distribution<double> u(-50, 50);
  std::lognormal_distribution<double> mass(0, 1);
  std::vector<std::array<double, 4>> clumps;  // centre, width
  for (int k = 0; k < 8; ++k) clumps.push_back({u(rng) * 0.8, u(rng) * 0.8, u(rng) * 0.8, std::exp2(-k * 0.7) * 4});
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = rng() % 12;
    for (int a = 0; a < 3; ++a) {
      const double x = k < clumps.size() ? std::normal_distribution<double>(clumps[k][a], clumps[k][3])(rng) : u(rng);
      c.position.push_back(std::clamp(x, -50.0, 49.999));
    }
    c.mass.push_back(mass(rng));
    c.type.push_back(static_cast<std::uint8_t>(i % 2));
  }
  return c;
}

// Every point of the tree, parents before children, with its parent cluster.
struct FlatTree {
  std::vector<double> position;  // 3 per point
  std::vector<double> mass;
  std::vector<float> bound;      // R, a, r per point (zeros for a leaf's particles)
  std::vector<bool> inner;       // a cluster (its node has children)
  std::vector<std::int64_t> parent;
  double total_mass = 0;
  std::size_t particles = 0;
};

FlatTree Flatten(const std::map<NodeKey, NodePoints>& nodes) {
  FlatTree t;
  std::map<NodeKey, std::size_t> first;
  for (const auto& [key, points] : nodes) {  // level-major: parents first
    first[key] = t.mass.size();
    const bool inner = !points.child_cluster.empty();
    for (std::size_t i = 0; i < points.size(); ++i) {
      t.position.insert(t.position.end(), &points.position[3 * i], &points.position[3 * i] + 3);
      t.mass.push_back(points.weight[i]);
      for (int k = 0; k < 3; ++k) t.bound.push_back(inner ? points.refine_bound[3 * i + k] : 0.0f);
      t.inner.push_back(inner);
      t.parent.push_back(-1);
      if (!inner) {
        t.total_mass += points.weight[i];
        ++t.particles;
      }
    }
  }
  for (const auto& [key, points] : nodes) {
    std::size_t entry = 0;
    for (int o = 0; o < 8 && !points.child_cluster.empty(); ++o) {
      const auto child = nodes.find(key.Child(o));
      if (child == nodes.end()) continue;
      for (std::size_t k = 0; k < child->second.size(); ++k) {
        t.parent[first[child->first] + k] = static_cast<std::int64_t>(first[key] + points.child_cluster[entry++]);
      }
    }
    EXPECT_EQ(entry, points.child_cluster.size()) << key.Path();
  }
  return t;
}

// E = s / sqrt(1 + s / r), s = a / (p D / f)^2, in float (the renderer's,
// render/shaders/splat_point.glsl), D the distance from the camera to the
// point's sphere (E infinite at 0), p half a pixel, f a focal length of 600
// pixels.
std::vector<float> ErrorBounds(const FlatTree& t, const std::array<double, 3>& camera) {
  constexpr float kPixelOverFocal = 0.5f / 600.0f;
  std::vector<float> error(t.mass.size(), 0.0f);
  for (std::size_t i = 0; i < error.size(); ++i) {
    if (!t.inner[i]) continue;
    float d2 = 0;
    for (int a = 0; a < 3; ++a) {
      const auto d = static_cast<float>(t.position[3 * i + a] - camera[a]);
      d2 += d * d;
    }
    const float gap = std::max(0.0f, std::sqrt(d2) - t.bound[3 * i]);
    const float a = t.bound[3 * i + 1], r = t.bound[3 * i + 2];
    const float q = kPixelOverFocal * gap;
    const float spread = a / (q * q);
    error[i] = gap > 0 && std::isfinite(spread) ? spread / std::sqrt(1 + spread / r) : INFINITY;
  }
  return error;
}

TEST(ClusterCut, EveryCameraAndThresholdDrawsEachParticleOnce) {
  std::mt19937_64 rng(7);
  const ParticleChunk particles = Clumps(rng, 30000);
  SubtreeOptions options;
  options.capacity = 200;  // clusters (the default) over several levels
  std::map<NodeKey, NodePoints> nodes;
  BuildSubtree(particles, NodeKey::Root(), kCube, options, [&](NodeKey key, const NodePoints& points) {
    nodes[key] = DecodeBlock(EncodeBlock(points, key, kCube), kAllColumns | kClusterLinkColumns, key, kCube, "cut")
                     .points;
  });
  const FlatTree tree = Flatten(nodes);
  ASSERT_EQ(tree.particles, particles.size());
  for (std::size_t i = nodes.begin()->second.size(); i < tree.parent.size(); ++i) ASSERT_GE(tree.parent[i], 0) << i;

  std::uniform_real_distribution<double> inside(-50, 50), outside(-300, 300);
  std::size_t cuts = 0, partial_cuts = 0;
  for (int c = 0; c < 40; ++c) {
    // Half the cameras among the particles, half around the cube.
    const std::array<double, 3> camera = c % 2 == 0 ? std::array<double, 3>{inside(rng), inside(rng), inside(rng)}
                                                    : std::array<double, 3>{outside(rng), outside(rng), outside(rng)};
    const std::vector<float> error = ErrorBounds(tree, camera);
    // The largest finite E (it is infinite for clusters whose spheres hold the camera).
    float highest = 0;
    for (const float e : error) {
      if (std::isfinite(e)) highest = std::max(highest, e);
    }
    std::vector<float> thresholds = {0.0f, std::numeric_limits<float>::infinity()};
    for (int k = 0; k <= 24; ++k) thresholds.push_back(highest * std::pow(10.0f, -0.25f * static_cast<float>(k)));
    // Each threshold also just at a point's own E, where ties decide.
    for (int k = 0; k < 8; ++k) thresholds.push_back(error[rng() % error.size()]);
    for (const float tau : thresholds) {
      // Parents come before their points: how many of a point's ancestors
      // are drawn is known when it is reached.
      std::vector<std::uint8_t> draw(tree.mass.size(), 0), drawn_above(tree.mass.size(), 0);
      std::size_t drawn = 0, twice_or_never = 0;
      double mass = 0;
      for (std::size_t i = 0; i < tree.mass.size(); ++i) {
        const std::int64_t p = tree.parent[i];
        const bool parent_refines = p < 0 || error[static_cast<std::size_t>(p)] > tau;
        draw[i] = (!tree.inner[i] || error[i] <= tau) && parent_refines;
        if (p >= 0) {
          const auto up = static_cast<std::size_t>(p);
          drawn_above[i] = static_cast<std::uint8_t>(std::min(2, drawn_above[up] + draw[up]));
        }
        if (draw[i]) {
          ++drawn;
          mass += tree.mass[i];
        }
        if (!tree.inner[i] && drawn_above[i] + draw[i] != 1) ++twice_or_never;
      }
      ASSERT_EQ(twice_or_never, 0u) << "camera " << c << ", threshold " << tau;
      EXPECT_NEAR(mass, tree.total_mass, 1e-9 * tree.total_mass) << "camera " << c << ", threshold " << tau;
      ++cuts;
      if (drawn > nodes.begin()->second.size() && drawn < tree.particles) ++partial_cuts;
    }
  }
  // Most cuts lie between the root's clusters and every particle.
  EXPECT_GT(partial_cuts, cuts / 2) << partial_cuts << " of " << cuts;
}

}  // namespace
}  // namespace octocosm
