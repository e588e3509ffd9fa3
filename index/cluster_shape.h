// The shape of a cluster's blob: how the particles a coarse point stands for
// spread along each direction, so that the cluster of a filament is drawn as
// a blob stretched along the filament rather than a round one that leaves
// the filament beaded.
//
// A cluster's covariance C (symmetric 3x3: the members' mass-weighted outer
// products of their offsets from the centre of mass, plus each member's own
// blob covariance) is kept as a size and a shape. The smoothing length holds
// the size: trace(C) / 3 = kKernelVariancePerH2 h^2 (index/aggregator.h),
// the round blob of the same total variance, which is what a reader that
// ignores shapes draws. The shape is S = C / (trace(C) / 3): trace 3, the
// identity for a round blob. Its six distinct entries (xx, yy, zz, xy, xz,
// yz) are stored in a byte each.
//
// Shapes are pulled towards the sphere, S' = (1 - kShapeFloor) S +
// kShapeFloor I, so that no axis is thinner than sqrt(kShapeFloor) of the
// mean: a blob is at most sqrt((3 - 2 f) / f) = 6.8 times longer than wide,
// which bounds the pixels a renderer spends on it and keeps the stored matrix
// positive definite through rounding. The trace, and so the size, stays.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace octocosm {

// Entries of a symmetric 3x3 matrix: xx, yy, zz, xy, xz, yz.
using SymmetricMatrix = std::array<double, 6>;

inline constexpr double kShapeFloor = 1.0 / 16.0;
// The shape of a round blob, as stored.
inline constexpr std::array<std::uint8_t, 6> kRoundShapeCode = {85, 85, 85, 127, 127, 127};

// The stored shape of covariance `c`: normalized to trace 3, pulled towards
// the sphere, snapped to multiples of 2^-20 (so that last-bit differences in
// `c` give the same code), rounded to bytes (diagonal q = round(85 s), in [0, 255];
// off-diagonal q = 127 + round(254 s / 3), in [0, 254]). A covariance
// without a positive finite trace gives the round shape.
std::array<std::uint8_t, 6> EncodeShape(const SymmetricMatrix& c);

// The shape S that `code` stores (trace 3 up to rounding).
SymmetricMatrix DecodeShape(const std::array<std::uint8_t, 6>& code);

// The shape of a round blob: the identity.
inline constexpr SymmetricMatrix kRoundShape = {1, 1, 1, 0, 0, 0};

// Point k's code in a shape column (NodePoints::shape).
inline std::array<std::uint8_t, 6> ShapeCodeAt(const std::vector<std::uint8_t>& column, std::size_t k) {
  std::array<std::uint8_t, 6> code{};
  for (int i = 0; i < 6; ++i) code[i] = column[6 * k + i];
  return code;
}

}  // namespace octocosm
