// Test helpers: read a dataset store back and check the octree invariants.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <unordered_map>
#include <vector>

#include "index/block_codec.h"
#include "index/dataset.h"

namespace octocosm::testing_support {

struct LeafPoint {
  double x[3];
  double weight;
  std::uint8_t type;
  NodeKey leaf;
  double node_mass;  // sum of the leaf's weights: one weight unit is node_mass / kWeightTotalUnits
  double smoothing;  // as decoded
  // The vector columns (indexed by VectorColumn), whether the leaf has each,
  // and the codec's error bound of each component in this leaf's block:
  // half a step of the block's range, (max - min) / 131070, plus float rounding.
  std::array<std::array<float, 3>, kVectorColumnCount> vectors{};
  std::array<bool, kVectorColumnCount> present{};
  std::array<std::array<double, 3>, kVectorColumnCount> bound{};

  bool Has(VectorColumn c) const { return present[static_cast<std::size_t>(c)]; }
  const std::array<float, 3>& Vector(VectorColumn c) const { return vectors[static_cast<std::size_t>(c)]; }
  double Bound(VectorColumn c, int axis) const { return bound[static_cast<std::size_t>(c)][static_cast<std::size_t>(axis)]; }
};

// Per component, the error bound of a quantized vector column in one block.
inline std::array<double, 3> QuantizationBound(const std::vector<float>& column) {
  std::array<double, 3> bound{};
  for (int a = 0; a < 3 && !column.empty(); ++a) {
    double lo = column[a], hi = column[a];
    for (std::size_t i = a; i < column.size(); i += 3) lo = std::min<double>(lo, column[i]), hi = std::max<double>(hi, column[i]);
    bound[a] = (hi - lo) / 131070 * (1 + 1e-6) + 4.0 * std::max(-lo, hi) * 0x1p-23;
  }
  return bound;
}

struct TreeCheck {
  std::unordered_map<std::uint64_t, LeafPoint> leaf_points;  // by ID
  std::map<std::uint64_t, std::vector<Bytes>> blocks;       // raw blocks by key, for comparisons
  std::uint64_t nodes = 0;
};

// Empty when both stores hold the same blocks; else names the first difference.
inline std::string FirstDifference(const TreeCheck& a, const TreeCheck& b) {
  if (a.blocks.size() != b.blocks.size()) {
    return std::to_string(a.blocks.size()) + " vs " + std::to_string(b.blocks.size()) + " blocks";
  }
  std::string differing;
  for (auto ia = a.blocks.begin(), ib = b.blocks.begin(); ia != a.blocks.end(); ++ia, ++ib) {
    if (ia->first != ib->first) return "node " + NodeKey::FromValue(ia->first).Path() + " vs " + NodeKey::FromValue(ib->first).Path();
    if (ia->second != ib->second) differing += " " + NodeKey::FromValue(ia->first).Path();
  }
  return differing.empty() ? "" : "blocks differ:" + differing;
}

// Walks every block of an epoch and checks the octree invariants.
inline TreeCheck CheckTree(const Dataset& dataset, std::uint32_t epoch) {
  TreeCheck check;
  const Cube& cube = dataset.cube(epoch);
  std::set<std::uint64_t> keys;
  dataset.store().Scan(epoch, 0, ~std::uint64_t{0}, [&](const IndexEntry& e) {
    keys.insert(e.key);
    return true;
  });
  std::unordered_map<std::uint64_t, double> own, below;
  for (std::uint64_t k : keys) {
    const NodeKey key = NodeKey::FromValue(k);
    bool leaf = true;
    for (int o = 0; o < 8 && key.level() < kMaxLevel; ++o) leaf &= !keys.count(key.Child(o).value());
    const Bytes bytes = dataset.store().ReadBlock({epoch, k});
    check.blocks[k].push_back(bytes);
    const DecodedBlock block = DecodeBlock(bytes, kAllColumns, key, cube, "test");
    const NodePoints& p = block.points;
    // The one documented exception: a leaf at the depth limit holds whatever reached it.
    if (!(leaf && key.level() == dataset.max_level())) {
      EXPECT_LE(p.size(), dataset.capacity()) << key.Path();
    }
    if (key.level() > 0) {
      EXPECT_TRUE(keys.count(key.Parent().value())) << "orphan " << key.Path();
    }
    double sum = 0;
    for (double w : p.weight) sum += w;
    own[k] = sum;
    if (key.level() > 0) below[key.Parent().value()] += sum;
    const NodeCube node = cube.NodeCubeOf(key);
    for (std::size_t i = 0; i < p.size(); ++i) {
      for (int a = 0; a < 3; ++a) {
        EXPECT_GE(p.position[3 * i + a], node.origin[a]);
        EXPECT_LE(p.position[3 * i + a], node.origin[a] + node.size);
      }
    }
    if (leaf) {
      EXPECT_FALSE(p.id.empty());
      const auto columns = VectorColumns(p);
      std::array<std::array<double, 3>, kVectorColumnCount> bounds;
      for (std::size_t v = 0; v < kVectorColumnCount; ++v) bounds[v] = QuantizationBound(*columns[v]);
      for (std::size_t i = 0; i < p.size(); ++i) {
        LeafPoint lp{{p.position[3 * i], p.position[3 * i + 1], p.position[3 * i + 2]}, p.weight[i], p.type[i], key, sum,
                     p.smoothing[i]};
        lp.bound = bounds;
        for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
          lp.present[v] = !columns[v]->empty();
          for (int a = 0; a < 3 && lp.present[v]; ++a) lp.vectors[v][a] = (*columns[v])[3 * i + a];
        }
        EXPECT_TRUE(check.leaf_points.emplace(p.id[i], lp).second) << "ID " << p.id[i] << " in two leaves";
      }
    }
    ++check.nodes;
  }
  for (const auto& [k, sum] : below) {
    EXPECT_NEAR(own.at(k), sum, 1e-12 * sum) << "weights of " << NodeKey::FromValue(k).Path() << " vs its children";
  }
  return check;
}


// Particles per type among the leaves.
inline std::map<int, std::uint64_t> TypeCounts(const TreeCheck& check) {
  std::map<int, std::uint64_t> counts;
  for (const auto& [id, p] : check.leaf_points) ++counts[p.type];
  return counts;
}

}  // namespace octocosm::testing_support
