// Each point's leaf in PCL's adaptive octree, for comparison with octocosm's
// (index/subtree_builder.h).
//
// pcl::octree::OctreePointCloudPointVector with dynamic depth splits a leaf
// when a point arrives at a leaf that already holds `capacity` points, down to
// its depth limit, and never creates empty children. After all points are in,
// a node is therefore a leaf exactly when it holds at most `capacity` points
// or sits at the depth limit: octocosm's rule. (PCL's root is always split;
// octocosm's root is a leaf when all points fit in it, so there must be more
// than `capacity` points.)
//
// How PCL's keys are made to be octocosm's keys, exactly:
//  - Resolution and box. PCL gets resolution size / 2^max_level (exact: a
//    power-of-two scaling) and the bounding box [origin, origin + size). Its
//    depth is then max_level and the box is not re-centred (PCL pads a box
//    whose edge is not 2^depth resolutions; this one is). Both are checked
//    after PCL has set them up, and again after the points are in (a point
//    outside the box would make PCL grow a level).
//  - Arithmetic. PCL's key at the deepest level is
//    (uint)((double(x) - min) / resolution); octocosm's cell is
//    floor(((x - origin) / size) * 2^L) (index/cube.h). The difference
//    x - origin is the same double in both; dividing by size / 2^L and
//    dividing by size then multiplying by 2^L give the same double, because
//    scaling by a power of two is exact and each is one correctly rounded
//    division; truncation equals floor for points at or above the origin. A
//    node's key at a shallower depth is the prefix of the deepest key in both.
//    So every point, on a cell face or not, gets the same key in any cube.
//  - Points are float32 in PCL, so they must be float32 values
//    (Error::InvalidArgument otherwise), and inside [origin, origin + size):
//    octocosm puts a point on the upper face (x == origin + size) in the last
//    cell, where PCL would grow its tree, so such points are refused too.
// The key of a leaf at PCL depth d comes from its iterator: d bits per axis,
// the cell at level d.
#pragma once

#include <cstddef>
#include <vector>

#include "index/cube.h"
#include "index/morton.h"

namespace octocosm::accuracy {

// The key (level = PCL depth, cell = PCL key) of the PCL leaf holding each
// point of `position` (x,y,z interleaved), in input order. 1 <= max_level <=
// kMaxLevel, capacity >= 1, more than `capacity` points. Throws
// Error::InvalidArgument when a precondition above fails or PCL did not take
// the box and depth it was given.
std::vector<NodeKey> PclOctreeLeaves(const std::vector<double>& position, const Cube& cube, std::size_t capacity,
                                     int max_level);

}  // namespace octocosm::accuracy
