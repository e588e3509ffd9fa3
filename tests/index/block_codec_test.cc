// Block codec: round trips over every column combination and size, the
// quantization bounds at every depth, exact weight sums, ranged decoding,
// the documented byte layout, and corruption sweeps (every byte flip, every
// truncation, structural fuzzing behind valid checksums) that must end in an
// Error or identical data, never undefined behaviour (run under ASan/UBSan).
#include "index/block_codec.h"

#include <gtest/gtest.h>
#include <xxhash.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "base/error.h"
#include "index/extended_sum.h"
#include "query/query.h"

namespace octocosm {
namespace {

constexpr ColumnSet kVelocityBit = ColumnBit(ColumnId::kVelocity);
constexpr ColumnSet kIdBit = ColumnBit(ColumnId::kId);
constexpr ColumnSet kDisplacementBit = ColumnBit(ColumnId::kDisplacement);
constexpr ColumnSet kDispersionBit = ColumnBit(ColumnId::kVelocityDispersion);
constexpr ColumnSet kShapeBit = ColumnBit(ColumnId::kShape);
// The optional columns, in block order.
constexpr std::array<ColumnId, 8> kOptionalColumns = {ColumnId::kVelocity,     ColumnId::kId,
                                                      ColumnId::kDisplacement, ColumnId::kNextVelocity,
                                                      ColumnId::kPrevDisplacement, ColumnId::kPrevVelocity,
                                                      ColumnId::kVelocityDispersion, ColumnId::kShape};

// n random points inside node `key`, optional columns as `optional` says.
NodePoints RandomPoints(std::mt19937_64& rng, std::size_t n, NodeKey key, const Cube& cube, ColumnSet optional) {
  const NodeCube node = cube.NodeCubeOf(key);
  std::uniform_real_distribution<double> unit(0, 1);
  std::lognormal_distribution<double> mass(0, 2);
  std::normal_distribution<float> vel(0, 300);
  NodePoints p;
  for (std::size_t i = 0; i < n; ++i) {
    for (;;) {
      double x[3];
      for (int a = 0; a < 3; ++a) x[a] = node.origin[a] + unit(rng) * node.size;
      if (!cube.Holds(key, x)) continue;  // rounding at the upper faces
      p.position.insert(p.position.end(), x, x + 3);
      break;
    }
    p.weight.push_back(mass(rng));
    p.smoothing.push_back(node.size * std::exp2(-16 * unit(rng)));
    p.type.push_back(static_cast<std::uint8_t>(rng() % 6));
    if (optional & kIdBit) p.id.push_back(rng());
    for (const ColumnId id : kVectorColumnIds) {
      if (!(optional & ColumnBit(id))) continue;
      const bool velocity = id == ColumnId::kVelocity || id == ColumnId::kNextVelocity || id == ColumnId::kPrevVelocity;
      for (int a = 0; a < 3; ++a) {
        VectorColumnOf(p, id)->push_back(velocity ? vel(rng) : static_cast<float>(unit(rng) - 0.5) * 0.01f);
      }
    }
    // Dispersions >= 0, a few exactly 0 (clusters of one particle).
    if (optional & kDispersionBit) p.velocity_dispersion.push_back(rng() % 8 == 0 ? 0.0f : std::fabs(vel(rng)) / 3);
    // Any codes: 0..255 on the diagonal, 0..254 off it.
    if (optional & kShapeBit) {
      for (int k = 0; k < 6; ++k) p.shape.push_back(static_cast<std::uint8_t>(rng() % (k < 3 ? 256 : 255)));
    }
  }
  OrderByOctant(p, key, cube);
  return p;
}

long double Sum(const std::vector<double>& v) {
  long double s = 0;
  for (double x : v) s += x;
  return s;
}

double Ulp(double x) { return std::nextafter(std::fabs(x), INFINITY) - std::fabs(x); }

// Checks `decoded` against the `original` points within the documented bounds.
void ExpectMatches(const NodePoints& original, const NodePoints& decoded, NodeKey key, const Cube& cube) {
  const std::size_t n = original.size();
  const NodeCube node = cube.NodeCubeOf(key);
  ASSERT_EQ(decoded.octant_offsets, original.octant_offsets);
  ASSERT_EQ(decoded.position.size(), 3 * n);
  const double half_quantum = node.size / 131072;
  for (std::size_t i = 0; i < 3 * n; ++i) {
    const int a = static_cast<int>(i % 3);
    const double slack = 2 * Ulp(std::fabs(node.origin[a]) + node.size);
    double error = decoded.position[i] - original.position[i];
    if (cube.periodic) error -= cube.size * std::round(error / cube.size);  // the point was wrapped into the box
    ASSERT_LE(std::fabs(error), half_quantum * (1 + 1e-9) + slack) << i;
    ASSERT_GE(decoded.position[i], node.origin[a]);
    ASSERT_LE(decoded.position[i], node.origin[a] + node.size);
  }
  ASSERT_EQ(decoded.weight.size(), n);
  if (n > 0) {
    const long double mass = Sum(original.weight);
    EXPECT_NEAR(static_cast<double>(Sum(decoded.weight) / mass), 1.0, 1e-12);
    const double unit = static_cast<double>(mass) / static_cast<double>(kWeightTotalUnits);
    for (std::size_t i = 0; i < n; ++i) ASSERT_LE(std::fabs(decoded.weight[i] - original.weight[i]), unit * 1.000001);
  }
  ASSERT_EQ(decoded.smoothing.size(), n);
  for (std::size_t i = 0; i < n; ++i) {
    // Half a step of 2^(1/2048) in log space.
    const double ratio = decoded.smoothing[i] / original.smoothing[i];
    ASSERT_LE(std::fabs(std::log2(ratio)), 1.0 / 4096 + 1e-12) << i;
  }
  EXPECT_EQ(decoded.type, original.type);
  EXPECT_EQ(decoded.id, original.id);
  for (const ColumnId id : kVectorColumnIds) {
    SCOPED_TRACE(ColumnName(id));
    const auto& orig = *VectorColumnOf(original, id);
    const auto& got = *VectorColumnOf(decoded, id);
    ASSERT_EQ(got.size(), orig.size());
    for (int a = 0; a < 3 && !orig.empty(); ++a) {
      float lo = orig[a], hi = orig[a];
      for (std::size_t i = a; i < orig.size(); i += 3) lo = std::min(lo, orig[i]), hi = std::max(hi, orig[i]);
      const double bound = (static_cast<double>(hi) - lo) / 131070 * (1 + 1e-6) + 4.0 * std::max(-lo, hi) * 0x1p-23;
      for (std::size_t i = a; i < orig.size(); i += 3) ASSERT_LE(std::fabs(got[i] - orig[i]), bound);
    }
  }
  ASSERT_EQ(decoded.velocity_dispersion.size(), original.velocity_dispersion.size());
  if (!original.velocity_dispersion.empty()) {
    const auto [lo, hi] = std::minmax_element(original.velocity_dispersion.begin(), original.velocity_dispersion.end());
    const double bound = (static_cast<double>(*hi) - *lo) / 131070 * (1 + 1e-6) + 4.0 * *hi * 0x1p-23;
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_GE(decoded.velocity_dispersion[i], 0.0f) << i;
      ASSERT_LE(std::fabs(decoded.velocity_dispersion[i] - original.velocity_dispersion[i]), bound) << i;
    }
  }
  ASSERT_EQ(decoded.shape, original.shape);  // codes, stored as they are
}

bool SamePoints(const NodePoints& a, const NodePoints& b) {
  bool same = a.position == b.position && a.weight == b.weight && a.smoothing == b.smoothing && a.id == b.id &&
              a.type == b.type && a.octant_offsets == b.octant_offsets;
  for (const ColumnId id : kVectorColumnIds) same &= *VectorColumnOf(a, id) == *VectorColumnOf(b, id);
  return same && a.velocity_dispersion == b.velocity_dispersion && a.shape == b.shape;
}

const Cube kCube{{-3.25, 12.0, 1000.0}, 77.5, false};

TEST(BlockCodec, RoundTripsEveryColumnCombinationAndSize) {
  std::mt19937_64 rng(1);
  const NodeKey key = NodeKey::FromPath("r30");
  for (ColumnSet optional = 0; optional < (1u << kOptionalColumns.size()); ++optional) {
    ColumnSet bits = 0;
    for (std::size_t c = 0; c < kOptionalColumns.size(); ++c) bits |= (optional >> c & 1) ? ColumnBit(kOptionalColumns[c]) : 0;
    const bool all = optional + 1 == (1u << kOptionalColumns.size());
    for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{2}, std::size_t{9}, all ? std::size_t{20000} : std::size_t{3000}}) {
      SCOPED_TRACE("optional " + std::to_string(optional) + " n " + std::to_string(n));
      const NodePoints points = RandomPoints(rng, n, key, kCube, bits);
      const Bytes block = EncodeBlock(points, key, kCube);
      const DecodedBlock decoded = DecodeBlock(block, kAllColumns, key, kCube, "test block");
      EXPECT_EQ(decoded.header.point_count, n);
      EXPECT_EQ(decoded.header.block_size, block.size());
      ExpectMatches(points, decoded.points, key, kCube);
    }
  }
}

TEST(BlockCodec, PositionErrorIsAtMostHalfAQuantumAtEveryDepth) {
  std::mt19937_64 rng(2);
  for (const Cube& cube : {kCube, Cube{{1e9, -1e9, 1e9}, 1.0, false}, Cube{{0, 0, 0}, 1e-6, true}}) {
    for (int level = 0; level <= kMaxLevel; ++level) {
      const std::uint32_t cells = 1u << level;
      const NodeKey key = NodeKey::FromCell(
          level, {static_cast<std::uint32_t>(rng() % cells), static_cast<std::uint32_t>(rng() % cells), cells - 1});
      NodePoints points = RandomPoints(rng, 500, key, cube, 0);
      // Points on the node's lower and upper faces too.
      const NodeCube node = cube.NodeCubeOf(key);
      for (int k = 0; k < 2; ++k) {
        const double face = k == 0 ? node.origin[2] : cube.origin[2] + cube.size;  // the cube's own upper face
        double x[3] = {node.origin[0], node.origin[1] + node.size / 3, face};
        // The periodic upper face wraps to the bottom cell, and a computed
        // node face can round into the neighbour: such points are not this node's.
        if (!cube.Holds(key, x)) continue;
        points.position.insert(points.position.end(), x, x + 3);
        points.weight.push_back(1);
        points.smoothing.push_back(node.size);
        points.type.push_back(0);
      }
      OrderByOctant(points, key, cube);
      const Bytes block = EncodeBlock(points, key, cube);
      const NodePoints decoded = DecodeBlock(block, kAllColumns, key, cube, "depth test").points;
      SCOPED_TRACE("level " + std::to_string(level));
      ExpectMatches(points, decoded, key, cube);
    }
  }
}

TEST(BlockCodec, WeightsSumExactlyInIntegerUnits) {
  std::mt19937_64 rng(3);
  const NodeKey key = NodeKey::FromPath("r7");
  for (int trial = 0; trial < 50; ++trial) {
    NodePoints points = RandomPoints(rng, 1 + rng() % 3000, key, kCube, 0);
    // Weights over 40 orders of magnitude: many round to zero units, the sum must not move.
    std::uniform_real_distribution<double> exponent(-20, 20);
    for (double& w : points.weight) w = std::pow(10.0, exponent(rng));
    const Bytes block = EncodeBlock(points, key, kCube);
    const BlockHeader header = DecodeBlockHeader(block, key, "w");
    const BlockColumn* column = header.Find(ColumnId::kWeight);
    ASSERT_NE(column, nullptr);
    std::uint64_t units = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      std::uint32_t u;
      std::memcpy(&u, block.data() + column->offset + 4 * i, 4);  // test host is little endian
      units += u;
    }
    EXPECT_EQ(units, kWeightTotalUnits);
    const NodePoints decoded = DecodeBlock(block, ColumnBit(ColumnId::kWeight), key, kCube, "w").points;
    EXPECT_NEAR(static_cast<double>(Sum(decoded.weight) / Sum(points.weight)), 1.0, 1e-12);
  }
}

// Equal weights take a shortcut in the encoder; the units must be what the
// largest-remainder rule gives: K / n each, rounded down, and the leftover
// units one each to the first points (equal remainders go to lower indices).
// The same weights with one nudged by an ulp take the general path and must
// agree on all other points.
TEST(BlockCodec, EqualWeightsGiveTheLeftoverUnitsToTheFirstPoints) {
  std::mt19937_64 rng(5);
  const NodeKey key = NodeKey::FromPath("r7");
  for (const std::size_t n : {std::size_t{1}, std::size_t{11}, std::size_t{3000}, std::size_t{16000}}) {
    NodePoints points = RandomPoints(rng, n, key, kCube, 0);
    std::fill(points.weight.begin(), points.weight.end(), 0.37);
    auto units_of = [&](const NodePoints& p) {
      const Bytes block = EncodeBlock(p, key, kCube);
      const BlockHeader header = DecodeBlockHeader(block, key, "w");
      const BlockColumn* column = header.Find(ColumnId::kWeight);
      if (column == nullptr) {
        ADD_FAILURE() << "the block has no weight column";
        return std::vector<std::uint32_t>();
      }
      std::vector<std::uint32_t> units(p.size());
      std::memcpy(units.data(), block.data() + column->offset, 4 * p.size());  // test host is little endian
      return units;
    };
    const std::vector<std::uint32_t> units = units_of(points);
    ASSERT_EQ(units.size(), n);
    const std::uint64_t share = kWeightTotalUnits / n, leftover = kWeightTotalUnits % n;
    std::uint64_t sum = 0;
    for (std::size_t i = 0; i < n; ++i) {
      EXPECT_EQ(units[i], share + (i < leftover ? 1 : 0)) << "n " << n << ", point " << i;
      sum += units[i];
    }
    EXPECT_EQ(sum, kWeightTotalUnits);
    if (n < 2) continue;
    NodePoints nudged = points;
    nudged.weight.back() = std::nextafter(nudged.weight.back(), 1.0);
    const std::vector<std::uint32_t> general = units_of(nudged);
    ASSERT_EQ(general.size(), n);
    for (std::size_t i = 0; i + 1 < n; ++i) {
      EXPECT_NEAR(static_cast<double>(general[i]), static_cast<double>(units[i]), 1.0) << "n " << n << ", point " << i;
    }
  }
}

// The general path's largest-remainder rule, on weights drawn from a few
// values so that remainders tie: every point gets the floor of its ideal
// share or one unit more; a point gets the extra unit before any point whose
// remainder is smaller, and among equal weights the lower indices get it.
TEST(BlockCodec, LeftoverUnitsGoToTheLargestRemaindersTiesToLowerIndices) {
  std::mt19937_64 rng(11);
  const NodeKey key = NodeKey::FromPath("r7");
  for (int trial = 0; trial < 40; ++trial) {
    NodePoints points = RandomPoints(rng, 2 + rng() % 5000, key, kCube, 0);
    std::array<double, 3> values;
    for (double& v : values) v = std::uniform_real_distribution<double>(0.1, 10.0)(rng);
    std::vector<int> value_of(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) {
      value_of[i] = static_cast<int>(rng() % 3);
      points.weight[i] = values[value_of[i]];
    }
    const Bytes block = EncodeBlock(points, key, kCube);
    const BlockHeader header = DecodeBlockHeader(block, key, "w");
    const BlockColumn* column = header.Find(ColumnId::kWeight);
    ASSERT_NE(column, nullptr);
    std::vector<std::uint32_t> units(points.size());
    std::memcpy(units.data(), block.data() + column->offset, 4 * units.size());  // test host is little endian
    long double total = 0;
    for (double w : points.weight) total += w;
    std::array<long double, 3> ideal, remainder;
    for (int v = 0; v < 3; ++v) {
      ideal[v] = values[v] / total * static_cast<long double>(kWeightTotalUnits);
      remainder[v] = ideal[v] - std::floor(ideal[v]);
    }
    std::array<bool, 3> some_without_extra{}, some_with_extra{};
    for (std::size_t i = 0; i < units.size(); ++i) {
      const int v = value_of[i];
      const auto floor = static_cast<std::uint32_t>(std::floor(ideal[v]));
      ASSERT_TRUE(units[i] == floor || units[i] == floor + 1) << "trial " << trial << " point " << i;
      if (units[i] == floor + 1) {
        ASSERT_FALSE(some_without_extra[v]) << "trial " << trial << ": point " << i
                                            << " has the extra unit after a lower one of equal weight had none";
        some_with_extra[v] = true;
      } else {
        some_without_extra[v] = true;
      }
    }
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) {
        // Remainders this far apart are ordered the same in any precision.
        if (some_with_extra[a] && some_without_extra[b] && remainder[b] > remainder[a] + 1e-6L) {
          ADD_FAILURE() << "trial " << trial << ": weight " << values[a] << " got an extra unit before weight "
                        << values[b] << " with a larger remainder";
        }
      }
    }
  }
}

// The same rule on weights whose remainders are nearly all distinct and
// spread over [0, 1), in blocks of up to a parent's 16000 points: the units
// equal those of a plain reference that orders the points by remainder
// (largest first, ties to the lower index), computed in the encoder's
// precision. Some weights repeat, so some remainders tie across the cut.
TEST(BlockCodec, LeftoverUnitsMatchAReferenceOrderOfTheRemainders) {
  std::mt19937_64 rng(17);
  const NodeKey key = NodeKey::FromPath("r7");
  for (const std::size_t n : {std::size_t{3}, std::size_t{100}, std::size_t{4097}, std::size_t{16000}}) {
    for (int trial = 0; trial < 4; ++trial) {
      NodePoints points = RandomPoints(rng, n, key, kCube, 0);
      std::lognormal_distribution<double> weight_of(0.0, 1.5);
      for (double& w : points.weight) w = weight_of(rng);
      for (std::size_t i = 0; i + 1 < n; i += 7) points.weight[i + 1] = points.weight[i];
      const Bytes block = EncodeBlock(points, key, kCube);
      const BlockHeader header = DecodeBlockHeader(block, key, "w");
      const BlockColumn* column = header.Find(ColumnId::kWeight);
      ASSERT_NE(column, nullptr);
      std::vector<std::uint32_t> units(n);
      std::memcpy(units.data(), block.data() + column->offset, 4 * n);  // test host is little endian

      const double units_per_weight =
          static_cast<double>(static_cast<long double>(kWeightTotalUnits) / ExtendedSum(points.weight));
      std::vector<std::uint64_t> expected(n);
      std::vector<double> remainder(n);
      std::uint64_t assigned = 0;
      for (std::size_t i = 0; i < n; ++i) {
        const double ideal = points.weight[i] * units_per_weight;
        expected[i] = static_cast<std::uint64_t>(ideal);
        remainder[i] = ideal - static_cast<double>(expected[i]);
        assigned += expected[i];
      }
      ASSERT_LT(assigned, kWeightTotalUnits) << "n " << n << ": the floors leave units over";
      ASSERT_LT(kWeightTotalUnits - assigned, n);
      std::vector<std::size_t> order(n);
      for (std::size_t i = 0; i < n; ++i) order[i] = i;
      std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        return remainder[a] != remainder[b] ? remainder[a] > remainder[b] : a < b;
      });
      for (std::size_t j = 0; j < kWeightTotalUnits - assigned; ++j) ++expected[order[j]];
      for (std::size_t i = 0; i < n; ++i) {
        ASSERT_EQ(units[i], expected[i]) << "n " << n << ", trial " << trial << ", point " << i;
      }
    }
  }
}

TEST(BlockCodec, RangedDecodeEqualsFullDecode) {
  std::mt19937_64 rng(4);
  const NodeKey key = NodeKey::FromPath("r0123");
  const NodePoints points = RandomPoints(rng, 777, key, kCube, kAllColumns);
  const Bytes block = EncodeBlock(points, key, kCube);
  const NodePoints full = DecodeBlock(block, kAllColumns, key, kCube, "full").points;

  // A reader that fetches only what it needs, each piece into its own buffer.
  const Bytes fixed(block.begin(), block.begin() + kBlockFixedHeaderSize);
  const std::size_t header_size = DecodeBlockHeaderSize(fixed, "ranged");
  const Bytes prefix(block.begin(), block.begin() + static_cast<std::ptrdiff_t>(header_size));
  const BlockHeader header = DecodeBlockHeader(prefix, key, "ranged");
  // Every attribute column (the cluster links are a test of their own).
  constexpr int kAttributes = std::popcount(kAllColumns);
  EXPECT_EQ(header.columns.size(), static_cast<std::size_t>(kAttributes));
  for (ColumnSet wanted = 1; wanted < (1u << kAttributes); wanted += 5) {
    NodePoints ranged;
    for (int raw = 1; raw <= kAttributes; ++raw) {
      const auto id = static_cast<ColumnId>(raw);
      if (!(wanted & (1u << (raw - 1)))) continue;
      const BlockColumn* c = header.Find(id);
      ASSERT_NE(c, nullptr);
      const Bytes bytes(block.begin() + static_cast<std::ptrdiff_t>(c->offset),
                        block.begin() + static_cast<std::ptrdiff_t>(c->offset + c->length));
      DecodeColumn(header, id, bytes, kCube, "ranged", ranged);
    }
    const NodePoints subset = DecodeBlock(block, wanted << 1, key, kCube, "subset").points;
    EXPECT_TRUE(SamePoints(ranged, subset)) << wanted;
    if (wanted & 1) {
      EXPECT_EQ(ranged.position, full.position);
    }
    if (wanted & (1u << 4)) {
      EXPECT_EQ(ranged.id, full.id);
    }
  }
}

// The layout documented at the top of block_codec.h, read back field by field.
TEST(BlockCodec, BytesFollowTheDocumentedLayout) {
  const NodeKey key = NodeKey::FromPath("r5");  // cell (1, 0, 1) at level 1
  const Cube cube{{0, 0, 0}, 2, false};
  NodePoints p;
  p.position = {1.5, 0.25, 1.0, 1.0 + 0.5 / 65536, 0.75, 1.75};
  p.weight = {1, 3};
  p.smoothing = {1.0, 0.5};
  p.type = {4, 1};
  p.id = {0x0102030405060708ull, 42};
  OrderByOctant(p, key, cube);
  // Point 0 has the top bit of x only (octant 1), point 1 those of y and z (octant 6).
  ASSERT_EQ(p.octant_offsets, (std::array<std::uint32_t, 9>{0, 0, 1, 1, 1, 1, 1, 2, 2}));
  const Bytes b = EncodeBlock(p, key, cube);
  auto u16 = [&](std::size_t at) { return static_cast<unsigned>(b[at] | b[at + 1] << 8); };
  auto u32 = [&](std::size_t at) { return u16(at) | (static_cast<std::uint32_t>(u16(at + 2)) << 16); };
  auto u64 = [&](std::size_t at) { return u32(at) | (static_cast<std::uint64_t>(u32(at + 4)) << 32); };
  EXPECT_EQ(std::string(b.begin(), b.begin() + 4), "OCBK");
  EXPECT_EQ(u16(4), 1u);
  const std::size_t header_size = 72 + 56 * 5 + 8;
  EXPECT_EQ(u16(6), header_size);
  EXPECT_EQ(u64(8), b.size());
  EXPECT_EQ(u64(16), key.value());
  EXPECT_EQ(u32(24), 2u);
  EXPECT_EQ(u16(28), 5u);
  EXPECT_EQ(u32(32 + 4 * 1), 0u);  // octant 1 starts at point 0
  EXPECT_EQ(u32(32 + 4 * 2), 1u);  // and ends at point 1
  EXPECT_EQ(u64(header_size - 8), XXH3_64bits(b.data(), header_size - 8));
  // Directory: position, weight, smoothing, id, type, contiguous.
  const int ids[5] = {1, 2, 3, 5, 6};
  const std::size_t widths[5] = {6, 4, 2, 8, 1};
  std::size_t offset = header_size;
  for (int c = 0; c < 5; ++c) {
    const std::size_t e = 72 + 56 * c;
    EXPECT_EQ(b[e], ids[c]);
    EXPECT_EQ(b[e + 1], 1);
    EXPECT_EQ(u64(e + 8), offset);
    EXPECT_EQ(u64(e + 16), 2 * widths[c]);
    EXPECT_EQ(u64(e + 24), XXH3_64bits(b.data() + offset, 2 * widths[c]));
    offset += 2 * widths[c];
  }
  EXPECT_EQ(offset, b.size());
  // Position of point 0 (in octant 0): node origin (1, 0, 1), edge 1.
  const std::size_t pos = header_size;
  EXPECT_EQ(u16(pos + 0), 32768u);  // x = 1.5: the top bit, octant 1
  EXPECT_EQ(u16(pos + 2), 16384u);  // y = 0.25
  EXPECT_EQ(u16(pos + 4), 0u);      // z = 1.0, on the node's lower face
  EXPECT_EQ(u16(pos + 6), 0u);      // x = 1 + half a quantum still rounds down
  // Weights 1 : 3 of K units; unit = 4 / K.
  EXPECT_EQ(u32(pos + 12), kWeightTotalUnits / 4);
  EXPECT_EQ(u32(pos + 16), kWeightTotalUnits / 4 * 3);
  double unit;
  const std::uint64_t unit_bits = u64(72 + 56 + 32);
  std::memcpy(&unit, &unit_bits, 8);
  EXPECT_DOUBLE_EQ(unit, 4.0 / static_cast<double>(kWeightTotalUnits));
  // Smoothing: h = s * 2^(-24 + code / 2048); h = s -> 24 * 2048.
  EXPECT_EQ(u16(pos + 20), 24u * 2048);
  EXPECT_EQ(u16(pos + 22), 23u * 2048);
  EXPECT_EQ(u64(pos + 24), 0x0102030405060708ull);
  EXPECT_EQ(b[pos + 40], 4);
}

void ExpectCorruptOrSame(const Bytes& block, NodeKey key, ColumnSet wanted, const NodePoints& expected,
                         const std::string& what) {
  try {
    const NodePoints got = DecodeBlock(block, wanted, key, kCube, "fuzz").points;
    EXPECT_TRUE(SamePoints(got, expected)) << what;
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kCorruption) << what << ": " << e.what();
    EXPECT_NE(std::string(e.what()).find("fuzz"), std::string::npos);
  }
}

TEST(BlockCodec, EverySingleByteFlipIsCaughtOrHarmless) {
  std::mt19937_64 rng(5);
  const NodeKey key = NodeKey::FromPath("r44");
  const NodePoints points = RandomPoints(rng, 6, key, kCube, kAllColumns);
  const Bytes block = EncodeBlock(points, key, kCube);
  const NodePoints all = DecodeBlock(block, kAllColumns, key, kCube, "fuzz").points;
  const ColumnSet some = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kId);
  const NodePoints partial = DecodeBlock(block, some, key, kCube, "fuzz").points;
  for (std::size_t at = 0; at < block.size(); ++at) {
    for (const int flip : {0x01, 0x10, 0x80, 0xff}) {
      Bytes bad = block;
      bad[at] = static_cast<std::uint8_t>(bad[at] ^ flip);
      ExpectCorruptOrSame(bad, key, kAllColumns, all, "byte " + std::to_string(at));
      ExpectCorruptOrSame(bad, key, some, partial, "byte " + std::to_string(at) + " partial");
    }
  }
}

TEST(BlockCodec, EveryTruncationIsCorruption) {
  std::mt19937_64 rng(6);
  const NodeKey key = NodeKey::FromPath("r1");
  const Bytes block = EncodeBlock(RandomPoints(rng, 5, key, kCube, kIdBit), key, kCube);
  for (std::size_t size = 0; size < block.size(); ++size) {
    const Bytes cut(block.begin(), block.begin() + static_cast<std::ptrdiff_t>(size));  // exact-size buffer for ASan
    try {
      DecodeBlock(cut, kAllColumns, key, kCube, "cut");
      ADD_FAILURE() << "truncation to " << size << " bytes decoded";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kCorruption) << size;
    }
  }
}

// Rewrites every checksum so that corrupted structure gets past them.
void FixChecksums(Bytes& b) {
  if (b.size() < kBlockFixedHeaderSize) return;
  const std::size_t header_size = static_cast<std::size_t>(b[6] | b[7] << 8);
  if (header_size < 8 || header_size > b.size()) return;
  const std::size_t columns = (header_size - 8 - kBlockFixedHeaderSize) / kBlockDirectoryEntrySize;
  for (std::size_t c = 0; c < columns && kBlockFixedHeaderSize + 56 * (c + 1) <= header_size - 8; ++c) {
    std::uint8_t* e = b.data() + kBlockFixedHeaderSize + 56 * c;
    std::uint64_t offset = 0, length = 0;
    for (int i = 7; i >= 0; --i) offset = offset << 8 | e[8 + i], length = length << 8 | e[16 + i];
    if (offset > b.size() || length > b.size() - offset) continue;
    const std::uint64_t sum = XXH3_64bits(b.data() + offset, length);
    for (int i = 0; i < 8; ++i) e[24 + i] = static_cast<std::uint8_t>(sum >> (8 * i));
  }
  const std::uint64_t sum = XXH3_64bits(b.data(), header_size - 8);
  for (int i = 0; i < 8; ++i) b[header_size - 8 + i] = static_cast<std::uint8_t>(sum >> (8 * i));
}

TEST(BlockCodec, StructuralFuzzBehindValidChecksumsNeverMisbehaves) {
  std::mt19937_64 rng(7);
  const NodeKey key = NodeKey::FromPath("r26");
  const Bytes block = EncodeBlock(RandomPoints(rng, 4, key, kCube, kAllColumns), key, kCube);
  int decoded = 0, corrupt = 0, unsupported = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    Bytes bad = block;
    const int flips = 1 + static_cast<int>(rng() % 3);
    for (int f = 0; f < flips; ++f) {
      // Mostly the header and directory, where the structure lives.
      const std::size_t at = rng() % 4 ? rng() % std::min<std::size_t>(bad.size(), kBlockMaxHeaderSize) : rng() % bad.size();
      bad[at] = static_cast<std::uint8_t>(rng());
    }
    if (rng() % 8 == 0) bad.resize(rng() % bad.size());
    FixChecksums(bad);
    try {
      const DecodedBlock d = DecodeBlock(bad, kAllColumns, key, kCube, "fuzz");
      for (double x : d.points.position) ASSERT_TRUE(std::isfinite(x));
      ++decoded;
    } catch (const Error& e) {
      ASSERT_TRUE(e.kind() == ErrorKind::kCorruption || e.kind() == ErrorKind::kNotSupported) << e.what();
      (e.kind() == ErrorKind::kCorruption ? corrupt : unsupported)++;
    }
  }
  EXPECT_GT(corrupt, 1000);
  EXPECT_GT(unsupported, 10);  // a rewritten version field
  EXPECT_GT(decoded, 10);      // a changed parameter or value decodes to other data
}

TEST(BlockCodec, WrongKeyAndVersionAreReported) {
  std::mt19937_64 rng(8);
  const NodeKey key = NodeKey::FromPath("r3");
  Bytes block = EncodeBlock(RandomPoints(rng, 3, key, kCube, 0), key, kCube);
  try {
    DecodeBlock(block, kAllColumns, NodeKey::FromPath("r4"), kCube, "file.ocp block r4");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kCorruption);
    EXPECT_NE(std::string(e.what()).find("file.ocp block r4"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("r3"), std::string::npos);
  }
  block[4] = 2;
  FixChecksums(block);
  try {
    DecodeBlock(block, kAllColumns, key, kCube, "v2");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kNotSupported);
  }
}

// A block of some columns of another (what a renderer caches) decodes to
// those columns of the original, each column's encoding and parameters kept:
// IDs as u32 offsets and as u64, every subset holding the required columns.
TEST(BlockCodec, ColumnSubsetsDecodeLikeTheirColumnsOfTheWholeBlock) {
  std::mt19937_64 rng(23);
  const NodeKey key = NodeKey::FromPath("r25");
  for (const bool narrow_ids : {true, false}) {
    NodePoints points = RandomPoints(rng, 300, key, kCube, kAllColumns);
    if (narrow_ids) {
      for (std::size_t i = 0; i < points.size(); ++i) points.id[i] = (std::uint64_t{5} << 40) + 3 * i;
    }
    const Bytes block = EncodeBlock(points, key, kCube);
    const BlockHeader header = DecodeBlockHeader(block, key, "whole");
    ASSERT_EQ(header.Find(ColumnId::kId)->encoding, narrow_ids ? 2 : 1);
    std::vector<std::span<const std::uint8_t>> spans;
    for (const BlockColumn& c : header.columns) spans.push_back(std::span(block).subspan(c.offset, c.length));
    const ColumnSet required = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                               ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kType);
    for (const ColumnSet extra : {ColumnSet{0}, ColumnBit(ColumnId::kId), ColumnBit(ColumnId::kVelocity) | ColumnBit(ColumnId::kId),
                                  kAllColumns}) {
      const ColumnSet keep = required | extra;
      const Bytes subset = AssembleColumnSubset(header, keep, spans);
      const DecodedBlock from_subset = DecodeBlock(subset, kAllColumns, key, kCube, "subset");
      const NodePoints expected = DecodeBlock(block, keep, key, kCube, "whole").points;
      EXPECT_TRUE(SamePoints(from_subset.points, expected)) << narrow_ids << " " << keep;
      EXPECT_EQ(from_subset.points.id, expected.id);
      for (const BlockColumn& c : from_subset.header.columns) {
        EXPECT_EQ(c.encoding, header.Find(c.id)->encoding) << ColumnName(c.id);
        EXPECT_EQ(c.params, header.Find(c.id)->params) << ColumnName(c.id);
      }
    }
    try {
      std::vector<std::span<const std::uint8_t>> short_id = spans;
      short_id[4] = short_id[4].first(short_id[4].size() - 1);
      AssembleColumnSubset(header, kAllColumns, short_id);
      ADD_FAILURE() << "a column of the wrong length was assembled";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
      EXPECT_NE(std::string(e.what()).find("column 'id' has the wrong length"), std::string::npos) << e.what();
    }
  }
}

// The id column's two encodings: IDs spanning less than 2^32 are u32
// offsets from the smallest (encoding 2, params: u64 base), wider ones u64
// (encoding 1); both decode to the IDs given, at either end of the u64 range.
TEST(BlockCodec, IdsOfANarrowRangeAreOffsetsFromTheSmallest) {
  std::mt19937_64 rng(21);
  const NodeKey key = NodeKey::FromPath("r4");
  constexpr std::uint64_t kMax = std::numeric_limits<std::uint64_t>::max();
  constexpr std::uint64_t kSpan32 = std::numeric_limits<std::uint32_t>::max();
  struct Case {
    std::uint64_t lowest, highest;
    int encoding;
  };
  for (const Case& c : {Case{1, 2000, 2}, Case{0, kSpan32, 2}, Case{0, kSpan32 + 1, 1}, Case{kMax - kSpan32, kMax, 2},
                        Case{kMax - 5, kMax, 2}, Case{0, kMax, 1}, Case{77, 77, 2}}) {
    NodePoints points = RandomPoints(rng, 50, key, kCube, kAllColumns);
    for (std::uint64_t& id : points.id) id = c.lowest + rng() % (c.highest - c.lowest + 1 == 0 ? kMax : c.highest - c.lowest + 1);
    points.id[7] = c.highest;
    points.id[31] = c.lowest;
    const Bytes block = EncodeBlock(points, key, kCube);
    const BlockHeader header = DecodeBlockHeader(block, key, "ids");
    const BlockColumn* column = header.Find(ColumnId::kId);
    ASSERT_NE(column, nullptr);
    EXPECT_EQ(column->encoding, c.encoding) << c.lowest << ".." << c.highest;
    EXPECT_EQ(block[kBlockFixedHeaderSize + 56 * 4 + 1], c.encoding) << "the directory's encoding byte";
    EXPECT_EQ(column->length, (c.encoding == 2 ? 4u : 8u) * points.size());
    if (c.encoding == 2) {
      std::uint64_t base = 0;
      std::memcpy(&base, column->params.data(), 8);  // test host is little endian
      EXPECT_EQ(base, c.lowest);
      std::uint32_t offset = 0;
      std::memcpy(&offset, block.data() + column->offset + 4 * 7, 4);
      EXPECT_EQ(offset, c.highest - c.lowest);
    }
    const NodePoints decoded = DecodeBlock(block, kAllColumns, key, kCube, "ids").points;
    EXPECT_EQ(decoded.id, points.id) << c.lowest << ".." << c.highest;
  }
}

// Encoding 2 only for the id column, and offsets that would pass 2^64 - 1
// from their base, are corruption (the checksums rewritten to match).
TEST(BlockCodec, BadIdOffsetEncodingsAreCorruption) {
  std::mt19937_64 rng(22);
  const NodeKey key = NodeKey::FromPath("r4");
  NodePoints points = RandomPoints(rng, 20, key, kCube, kAllColumns);
  for (std::size_t i = 0; i < points.size(); ++i) points.id[i] = 1000 + i;
  const Bytes block = EncodeBlock(points, key, kCube);
  const std::size_t id_entry = kBlockFixedHeaderSize + 56 * 4;
  ASSERT_EQ(block[id_entry], 5) << "the fifth column is the id column";
  ASSERT_EQ(block[id_entry + 1], 2);
  const auto expect_corrupt = [&](Bytes bad, const std::string& message, const std::string& what) {
    FixChecksums(bad);
    try {
      DecodeBlock(bad, kAllColumns, key, kCube, "store/epoch-00000.pages block r4");
      ADD_FAILURE() << what << " decoded";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kCorruption) << what;
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << what << ": " << e.what();
      EXPECT_NE(std::string(e.what()).find("epoch-00000.pages block r4"), std::string::npos) << e.what();
    }
  };
  Bytes velocity_offsets = block;
  velocity_offsets[kBlockFixedHeaderSize + 56 * 3 + 1] = 2;  // the velocity column
  expect_corrupt(velocity_offsets, "column 'velocity': unknown encoding 2", "encoding 2 on velocity");
  Bytes encoding_three = block;
  encoding_three[id_entry + 1] = 3;
  expect_corrupt(encoding_three, "column 'id': unknown encoding 3", "encoding 3");
  Bytes wide_length = block;
  wide_length[id_entry + 1] = 1;  // 4n bytes where u64 IDs need 8n
  expect_corrupt(wide_length, "column 'id': 80 bytes for 20 points, expected 160", "encoding 1 with 4n bytes");
  Bytes overflowing = block;
  for (int i = 0; i < 8; ++i) overflowing[id_entry + 32 + i] = 0xFF;  // base 2^64 - 1, offsets up to 19
  expect_corrupt(overflowing, "passes 2^64 - 1", "an overflowing base");
}

// The encoder codes four points (twelve values) at a time and the rest one
// by one: every length around those groups gets each value's nearest code.
TEST(BlockCodec, VelocityCodesAreTheNearestOfTheRange) {
  std::mt19937_64 rng(12);
  const NodeKey key = NodeKey::FromPath("r3");
  for (const std::size_t n : {std::size_t{1}, std::size_t{3}, std::size_t{4}, std::size_t{5}, std::size_t{8},
                              std::size_t{37}, std::size_t{1000}}) {
    SCOPED_TRACE("n " + std::to_string(n));
    const NodePoints p = RandomPoints(rng, n, key, kCube, kVelocityBit);
    const NodePoints d = DecodeBlock(EncodeBlock(p, key, kCube), kAllColumns, key, kCube, "codes").points;
    ASSERT_EQ(d.velocity.size(), p.velocity.size());
    std::size_t checked = 0;
    for (int a = 0; a < 3; ++a) {
      double lo = p.velocity[a], hi = p.velocity[a];
      for (std::size_t i = a; i < p.velocity.size(); i += 3) {
        lo = std::min<double>(lo, p.velocity[i]);
        hi = std::max<double>(hi, p.velocity[i]);
      }
      if (hi == lo) continue;
      const double quantum = (hi - lo) / 65535.0;
      for (std::size_t i = a; i < p.velocity.size(); i += 3) {
        const double exact = (p.velocity[i] - lo) / quantum;
        if (std::fabs(exact - std::floor(exact) - 0.5) < 1e-3) continue;  // too near a half to call
        const double code = std::floor(exact + 0.5);
        ASSERT_NEAR((d.velocity[i] - lo) / quantum, code, 0.01) << "value " << i;
        ++checked;
      }
    }
    if (n > 1) {
      EXPECT_GT(checked, 0u);
    }
  }
}

TEST(BlockCodec, ExtremeVelocityRangesStayFinite) {
  std::mt19937_64 rng(10);
  const NodeKey key = NodeKey::FromPath("r6");
  NodePoints p = RandomPoints(rng, 64, key, kCube, kAllColumns);
  const float big = std::numeric_limits<float>::max();
  for (std::size_t i = 0; i < p.velocity.size(); ++i) {
    p.velocity[i] = (i % 2 ? big : -big) * (static_cast<float>(i % 5) / 4);
    p.next_velocity[i] = -p.velocity[i];
    p.prev_velocity[i] = p.velocity[(i + 3) % p.velocity.size()];
  }
  for (float& d : p.displacement) d = 1e-30f;  // a zero range
  for (float& d : p.prev_displacement) d = -1e-30f;
  const NodePoints d = DecodeBlock(EncodeBlock(p, key, kCube), kAllColumns, key, kCube, "extreme").points;
  for (std::size_t i = 0; i < p.velocity.size(); ++i) {
    for (const ColumnId id : {ColumnId::kVelocity, ColumnId::kNextVelocity, ColumnId::kPrevVelocity}) {
      const float got = (*VectorColumnOf(d, id))[i];
      ASSERT_TRUE(std::isfinite(got)) << ColumnName(id);
      ASSERT_LE(std::fabs(static_cast<double>(got) - (*VectorColumnOf(p, id))[i]), 2.0 * big / 131070 * 1.001);
    }
    ASSERT_EQ(d.displacement[i], 1e-30f);
    ASSERT_EQ(d.prev_displacement[i], -1e-30f);
  }
}

// Columns 8-10 (the epoch links) get every check that velocity and
// displacement get: their own checksum, their length, their range.
TEST(BlockCodec, EpochLinkColumnsAreCheckedLikeVelocity) {
  std::mt19937_64 rng(11);
  const NodeKey key = NodeKey::FromPath("r52");
  const NodePoints points = RandomPoints(rng, 30, key, kCube, kAllColumns);
  const Bytes block = EncodeBlock(points, key, kCube);
  const BlockHeader header = DecodeBlockHeader(block, key, "links");
  // All twelve columns, in id order.
  ASSERT_EQ(header.columns.size(), 12u);
  for (std::size_t c = 0; c < 12; ++c) EXPECT_EQ(static_cast<int>(header.columns[c].id), static_cast<int>(c + 1));
  auto expect_corrupt = [&](const Bytes& bad, ColumnSet wanted, const std::string& message) {
    try {
      DecodeBlock(bad, wanted, key, kCube, "links");
      ADD_FAILURE() << message;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kCorruption) << e.what();
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
    }
  };
  for (const ColumnId id : {ColumnId::kNextVelocity, ColumnId::kPrevDisplacement, ColumnId::kPrevVelocity}) {
    SCOPED_TRACE(ColumnName(id));
    const BlockColumn& column = *header.Find(id);
    EXPECT_EQ(column.length, 6u * points.size());
    const std::string name = std::string("column '") + ColumnName(id) + "': ";
    // A flipped value byte: the column's own checksum, found even when only it is read.
    Bytes bad = block;
    bad[column.offset + 7] ^= 0x20;
    expect_corrupt(bad, ColumnBit(id), name + "checksum mismatch");
    // A range with min > max behind valid checksums.
    bad = block;
    const std::size_t entry = kBlockFixedHeaderSize + kBlockDirectoryEntrySize * (static_cast<std::size_t>(id) - 1);
    const float min = 1, max = -1;
    std::memcpy(&bad[entry + 32], &min, 4);
    std::memcpy(&bad[entry + 32 + 12], &max, 4);
    FixChecksums(bad);
    expect_corrupt(bad, ColumnBit(id), name + "range of component 0");
    // A length that does not fit the point count.
    bad = block;
    bad[entry + 16] = static_cast<std::uint8_t>(bad[entry + 16] + 6);
    FixChecksums(bad);
    expect_corrupt(bad, kAllColumns, name);
  }
  // Id 15 is not a column of version 1.
  Bytes bad = block;
  bad[kBlockFixedHeaderSize + kBlockDirectoryEntrySize * 11] = 15;
  FixChecksums(bad);
  expect_corrupt(bad, kAllColumns, "unknown column id 15");
}

// Column 12: six byte codes a point, as given; an off-diagonal code of 255
// is refused by the encoder and reported as corruption by the decoder.
TEST(BlockCodec, ShapeCodesAreStoredAsTheyAreAndChecked) {
  std::mt19937_64 rng(41);
  const NodeKey key = NodeKey::FromPath("r3");
  NodePoints points = RandomPoints(rng, 20, key, kCube, kShapeBit);
  const Bytes block = EncodeBlock(points, key, kCube);
  const BlockHeader header = DecodeBlockHeader(block, key, "shape");
  const BlockColumn& column = *header.Find(ColumnId::kShape);
  ASSERT_EQ(column.length, 6u * points.size());
  EXPECT_TRUE(std::equal(points.shape.begin(), points.shape.end(), block.begin() + static_cast<std::ptrdiff_t>(column.offset)));
  EXPECT_EQ(DecodeBlock(block, kShapeBit, key, kCube, "shape").points.shape, points.shape);

  Bytes bad = block;
  bad[column.offset + 6 * 4 + 3] = 255;
  FixChecksums(bad);
  try {
    DecodeBlock(bad, kShapeBit, key, kCube, "shape");
    ADD_FAILURE() << "an off-diagonal code of 255 decoded";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kCorruption);
    EXPECT_NE(std::string(e.what()).find("column 'shape': off-diagonal code 255 at point 4"), std::string::npos) << e.what();
  }
  points.shape[6 * 2 + 5] = 255;
  EXPECT_THROW(EncodeBlock(points, key, kCube), Error);
  points.shape.pop_back();
  EXPECT_THROW(EncodeBlock(points, key, kCube), Error);
}

// Columns 13 and 14, the cluster links: child_cluster as u16 entries while
// the node has at most 2^16 points and u32 past it, its entry count in its
// parameters; refine_bound as f32 triples. Entries that name no point, run
// back to an earlier octant or leave a cluster without members, and bounds
// that are negative or not finite, are refused by the encoder and reported
// as corruption by the decoder.
TEST(BlockCodec, ClusterLinksRoundTripAndAreChecked) {
  std::mt19937_64 rng(43);
  const NodeKey key = NodeKey::FromPath("r6");
  for (const std::size_t n : {std::size_t{40}, std::size_t{70000}}) {
    SCOPED_TRACE(n);
    NodePoints points = RandomPoints(rng, n, key, kCube, kShapeBit);
    // Three children's points a cluster, each in its cluster's octant.
    for (std::uint32_t c = 0; c < n; ++c) points.child_cluster.insert(points.child_cluster.end(), {c, c, c});
    // Zeros, and values over 2^-40 .. 2^40 (each component's base follows its smallest).
    std::uniform_real_distribution<double> octaves(-40, 40);
    for (std::size_t i = 0; i < 3 * n; ++i) {
      points.refine_bound.push_back(i % 11 == 0 ? 0.0f : static_cast<float>(std::exp2(octaves(rng))));
    }
    const std::vector<float> exact = points.refine_bound;
    QuantizeRefineBounds(points.refine_bound);
    for (std::size_t i = 0; i < exact.size(); ++i) {
      ASSERT_GE(points.refine_bound[i], exact[i]) << i;
      ASSERT_LE(points.refine_bound[i], exact[i] * 1.0028f) << i << ": more than a code (2^(1/256)) above";
    }
    std::vector<float> twice = points.refine_bound;
    QuantizeRefineBounds(twice);
    EXPECT_EQ(twice, points.refine_bound) << "stored values stay as they are";
    const Bytes block = EncodeBlock(points, key, kCube);
    const BlockHeader header = DecodeBlockHeader(block, key, "links");
    const BlockColumn& links = *header.Find(ColumnId::kChildCluster);
    EXPECT_EQ(links.encoding, n <= 65536 ? kEncodingV1 : kEncodingChildClusterU32);
    EXPECT_EQ(links.length, (n <= 65536 ? 2u : 4u) * 3 * n);
    EXPECT_EQ(header.Find(ColumnId::kRefineBound)->length, 6u * n);
    const NodePoints decoded = DecodeBlock(block, kClusterLinkColumns, key, kCube, "links").points;
    EXPECT_EQ(decoded.child_cluster, points.child_cluster);
    EXPECT_EQ(decoded.refine_bound, points.refine_bound);
    EXPECT_TRUE(DecodeBlock(block, kAllColumns, key, kCube, "links").points.child_cluster.empty());
  }

  const std::size_t n = 12;
  NodePoints points = RandomPoints(rng, n, key, kCube, kShapeBit);
  for (std::uint32_t c = 0; c < n; ++c) points.child_cluster.insert(points.child_cluster.end(), {c, c});
  points.refine_bound.assign(3 * n, 1.0f);
  const Bytes block = EncodeBlock(points, key, kCube);
  const BlockHeader header = DecodeBlockHeader(block, key, "links");
  const BlockColumn& links = *header.Find(ColumnId::kChildCluster);
  const auto expect_corrupt = [&](Bytes bad, const std::string& message) {
    FixChecksums(bad);
    try {
      DecodeBlock(bad, kClusterLinkColumns, key, kCube, "links");
      ADD_FAILURE() << message;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kCorruption) << e.what();
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
    }
  };
  const auto with_entry = [&](std::size_t entry, std::uint16_t value) {
    Bytes bad = block;
    bad[links.offset + 2 * entry] = static_cast<std::uint8_t>(value);
    bad[links.offset + 2 * entry + 1] = static_cast<std::uint8_t>(value >> 8);
    return bad;
  };
  expect_corrupt(with_entry(5, 12), "column 'child_cluster': entry 5 names point 12 of 12");
  const auto octant_of = [&](std::uint32_t point) {
    int o = 0;
    while (point >= header.octant_offsets[o + 1]) ++o;
    return o;
  };
  ASSERT_LT(octant_of(0), octant_of(n - 1)) << "the first and last points lie in different octants";
  // The last entry names point 0: an earlier octant after a later one.
  expect_corrupt(with_entry(2 * n - 1, 0), "before one in octant");
  Bytes unnamed_bytes = with_entry(0, 1);
  unnamed_bytes[links.offset + 2] = 1;  // entry 1 as well
  expect_corrupt(unnamed_bytes, "point 0 holds none of the children's points");
  Bytes count = block;
  const std::size_t entry = kBlockFixedHeaderSize + kBlockDirectoryEntrySize * (header.columns.size() - 2);
  count[entry + 32] = static_cast<std::uint8_t>(count[entry + 32] + 1);  // one entry more than its bytes hold
  expect_corrupt(count, "column 'child_cluster': " + std::to_string(2 * 2 * n) + " bytes for " +
                            std::to_string(2 * n + 1) + " entries");
  // A base beyond the float range, and a code beyond it.
  const BlockColumn& bounds = *header.Find(ColumnId::kRefineBound);
  const std::size_t bounds_entry = kBlockFixedHeaderSize + kBlockDirectoryEntrySize * (header.columns.size() - 1);
  Bytes far = block;
  const std::int32_t base = 200;
  std::memcpy(&far[bounds_entry + 32 + 4], &base, 4);
  expect_corrupt(far, "column 'refine_bound': base 1 is 2^200");
  Bytes huge = block;
  huge[bounds.offset + 2 * 7] = 0xFF;
  huge[bounds.offset + 2 * 7 + 1] = 0xFF;
  expect_corrupt(huge, "column 'refine_bound': point 2 holds code 65535");

  NodePoints unnamed = points;
  unnamed.child_cluster[0] = unnamed.child_cluster[1] = 1;
  EXPECT_THROW(EncodeBlock(unnamed, key, kCube), Error);
  NodePoints infinite = points;
  infinite.refine_bound[4] = std::numeric_limits<float>::infinity();
  EXPECT_THROW(EncodeBlock(infinite, key, kCube), Error);
  NodePoints short_bounds = points;
  short_bounds.refine_bound.pop_back();
  EXPECT_THROW(EncodeBlock(short_bounds, key, kCube), Error);
}

// Column 11: u16 codes between the block's f32 min and max dispersion, as
// docs/FORMAT.md section 4 says, each the nearest of the range; its own
// checksum, length and range are checked; the encoder takes only finite
// values >= 0; and a block without it is the block it was before.
TEST(BlockCodec, VelocityDispersionFollowsTheDocumentedLayoutAndChecks) {
  std::mt19937_64 rng(31);
  const NodeKey key = NodeKey::FromPath("r16");
  NodePoints points = RandomPoints(rng, 50, key, kCube, kVelocityBit | kIdBit | kDispersionBit);
  points.velocity_dispersion[7] = 0.0f;  // the smallest, so min = 0
  points.velocity_dispersion[11] = 250.0f;
  for (float& s : points.velocity_dispersion) s = std::min(s, 250.0f);
  const Bytes block = EncodeBlock(points, key, kCube);
  const BlockHeader header = DecodeBlockHeader(block, key, "dispersion");
  ASSERT_EQ(header.columns.size(), 7u);
  const BlockColumn& column = header.columns.back();
  ASSERT_EQ(column.id, ColumnId::kVelocityDispersion);
  EXPECT_EQ(column.encoding, 1);
  EXPECT_EQ(column.length, 2u * points.size());
  EXPECT_EQ(column.offset + column.length, block.size()) << "the last column, after type";
  float min = -1, max = -1;
  std::memcpy(&min, column.params.data(), 4);
  std::memcpy(&max, column.params.data() + 4, 4);
  EXPECT_EQ(min, 0.0f);
  EXPECT_EQ(max, 250.0f);
  EXPECT_TRUE(std::all_of(column.params.begin() + 8, column.params.end(), [](std::uint8_t b) { return b == 0; }));
  const NodePoints decoded = DecodeBlock(block, kAllColumns, key, kCube, "dispersion").points;
  ASSERT_EQ(decoded.velocity_dispersion.size(), points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const unsigned q = block[column.offset + 2 * i] | block[column.offset + 2 * i + 1] << 8;
    EXPECT_LE(std::fabs(q - points.velocity_dispersion[i] / 250.0 * 65535), 0.5 + 1e-6) << i << ": the nearest code";
    EXPECT_FLOAT_EQ(decoded.velocity_dispersion[i], static_cast<float>(q * (250.0 / 65535))) << i;
  }
  EXPECT_EQ(decoded.velocity_dispersion[7], 0.0f);
  EXPECT_EQ(decoded.velocity_dispersion[11], 250.0f);

  // Without the column the block is the same block less its directory entry
  // and bytes: every other column byte for byte, its checksum and params too.
  NodePoints without = points;
  without.velocity_dispersion.clear();
  const Bytes plain = EncodeBlock(without, key, kCube);
  const BlockHeader plain_header = DecodeBlockHeader(plain, key, "plain");
  ASSERT_EQ(plain_header.columns.size(), 6u);
  EXPECT_EQ(plain.size(), block.size() - kBlockDirectoryEntrySize - column.length);
  for (std::size_t c = 0; c < plain_header.columns.size(); ++c) {
    const BlockColumn& a = plain_header.columns[c];
    const BlockColumn& b = header.columns[c];
    EXPECT_EQ(a.id, b.id);
    EXPECT_EQ(a.checksum, b.checksum);
    EXPECT_EQ(a.params, b.params);
    EXPECT_TRUE(std::equal(plain.begin() + static_cast<std::ptrdiff_t>(a.offset),
                           plain.begin() + static_cast<std::ptrdiff_t>(a.offset + a.length),
                           block.begin() + static_cast<std::ptrdiff_t>(b.offset)))
        << ColumnName(a.id);
  }
  EXPECT_TRUE(DecodeBlock(plain, kAllColumns, key, kCube, "plain").points.velocity_dispersion.empty());

  // Damage behind valid checksums, and a flipped value byte.
  auto expect_corrupt = [&](const Bytes& bad, ColumnSet wanted, const std::string& message) {
    try {
      DecodeBlock(bad, wanted, key, kCube, "store/epoch-00000.pages block r16");
      ADD_FAILURE() << message;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kCorruption) << e.what();
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("block r16"), std::string::npos) << e.what();
    }
  };
  const std::string name = "column 'velocity_dispersion': ";
  const std::size_t entry = kBlockFixedHeaderSize + kBlockDirectoryEntrySize * 6;
  Bytes bad = block;
  bad[column.offset + 5] ^= 0x10;
  expect_corrupt(bad, kDispersionBit, name + "checksum mismatch");
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  for (const auto& [lo, hi] : {std::pair{-1.0f, 250.0f}, std::pair{3.0f, 2.0f}, std::pair{nan, 250.0f},
                               std::pair{0.0f, inf}, std::pair{0.0f, nan}}) {
    SCOPED_TRACE(std::to_string(lo) + ", " + std::to_string(hi));
    bad = block;
    std::memcpy(&bad[entry + 32], &lo, 4);
    std::memcpy(&bad[entry + 36], &hi, 4);
    FixChecksums(bad);
    expect_corrupt(bad, kDispersionBit, name + "range is [");
  }
  bad = block;
  bad[entry + 16] = static_cast<std::uint8_t>(bad[entry + 16] + 2);
  FixChecksums(bad);
  expect_corrupt(bad, kAllColumns, name);
  // A range whose codes could round past max: decoded values stay <= max.
  bad = block;
  const float big = std::numeric_limits<float>::max();
  std::memcpy(&bad[entry + 36], &big, 4);
  FixChecksums(bad);
  for (const float s : DecodeBlock(bad, kDispersionBit, key, kCube, "big").points.velocity_dispersion) {
    ASSERT_TRUE(std::isfinite(s));
    ASSERT_GE(s, 0.0f);
  }

  // The encoder's contract.
  for (const float value : {-1e-3f, nan, inf}) {
    NodePoints p = points;
    p.velocity_dispersion[13] = value;
    try {
      EncodeBlock(p, key, kCube);
      ADD_FAILURE() << value;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
      EXPECT_NE(std::string(e.what()).find("velocity_dispersion of point 13"), std::string::npos) << e.what();
    }
  }
  NodePoints short_column = points;
  short_column.velocity_dispersion.pop_back();
  EXPECT_THROW(EncodeBlock(short_column, key, kCube), Error);
  // A constant column (all zero: clusters of one particle each) codes as 0 and decodes exactly.
  NodePoints zeros = points;
  std::fill(zeros.velocity_dispersion.begin(), zeros.velocity_dispersion.end(), 0.0f);
  EXPECT_EQ(DecodeBlock(EncodeBlock(zeros, key, kCube), kAllColumns, key, kCube, "zeros").points.velocity_dispersion,
            zeros.velocity_dispersion);
}

// Whatever reorders or selects a node's points moves each point's
// dispersion with it.
TEST(BlockCodec, ReorderingAndSelectingPointsKeepTheirDispersions) {
  std::mt19937_64 rng(32);
  const NodeKey key = NodeKey::FromPath("r43");
  NodePoints p = RandomPoints(rng, 300, key, kCube, kVelocityBit | kDispersionBit);
  // Each point's dispersion tied to its velocity, so a point can be recognised.
  const auto tied = [](const NodePoints& q) {
    if (q.velocity_dispersion.size() != q.size()) return false;
    for (std::size_t i = 0; i < q.size(); ++i) {
      if (q.velocity_dispersion[i] != std::fabs(q.velocity[3 * i])) return false;
    }
    return true;
  };
  for (std::size_t i = 0; i < p.size(); ++i) p.velocity_dispersion[i] = std::fabs(p.velocity[3 * i]);
  // Reversed, the points are no longer grouped by octant.
  NodePoints reversed;
  for (std::size_t i = p.size(); i-- > 0;) {
    reversed.position.insert(reversed.position.end(), &p.position[3 * i], &p.position[3 * i] + 3);
    reversed.velocity.insert(reversed.velocity.end(), &p.velocity[3 * i], &p.velocity[3 * i] + 3);
    reversed.weight.push_back(p.weight[i]);
    reversed.smoothing.push_back(p.smoothing[i]);
    reversed.type.push_back(p.type[i]);
    reversed.velocity_dispersion.push_back(p.velocity_dispersion[i]);
  }
  OrderByOctant(reversed, key, kCube);
  ASSERT_NE(reversed.position, p.position) << "the reversal must have moved points";
  EXPECT_TRUE(tied(reversed));
  std::vector<std::uint32_t> rows;
  for (std::uint32_t i = 0; i < p.size(); i += 3) rows.push_back(i);
  const NodePoints selected = SelectRows(reversed, rows);
  EXPECT_EQ(selected.size(), rows.size());
  EXPECT_TRUE(tied(selected));
  NodePoints kept = reversed;
  KeepPoints(kept, rows);
  EXPECT_TRUE(tied(kept));
  EXPECT_EQ(kept.velocity_dispersion, selected.velocity_dispersion);
}

TEST(BlockCodec, EncodeRejectsPointsThatBreakTheContract) {
  std::mt19937_64 rng(9);
  const NodeKey key = NodeKey::FromPath("r12");
  const NodePoints good = RandomPoints(rng, 40, key, kCube, kVelocityBit);
  // With and without kept grid points (the builder's form), the error names
  // the first offending point and what is wrong with it.
  for (const bool with_grid : {false, true}) {
    SCOPED_TRACE(with_grid ? "with grid points" : "positions only");
    auto expect_invalid = [&](NodePoints p, const char* what, const std::string& message = "") {
      if (with_grid) {
        p.grid.clear();
        for (std::size_t i = 0; i < p.size(); ++i) p.grid.push_back(kCube.FinestGridCoords(&p.position[3 * i]));
      }
      try {
        EncodeBlock(p, key, kCube);
        ADD_FAILURE() << what;
      } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument) << what;
        EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << what << ": " << e.what();
      }
    };
    NodePoints p = good;
    p.position[3 * 17] = kCube.origin[0] + kCube.size * 0.99;  // another node
    expect_invalid(p, "outside", "point 17 (");
    p = good;
    p.octant_offsets[8] = 39;
    expect_invalid(p, "offsets");
    p = good;
    ASSERT_GT(p.octant_offsets[2], p.octant_offsets[1]);
    ++p.octant_offsets[1];  // the first point of octant 1 listed in octant 0
    expect_invalid(p, "offsets disagree with positions",
                   "point " + std::to_string(good.octant_offsets[1]) + " of node r12 lies in child octant 1 but "
                   "octant_offsets put it in octant 0");
    p = good;
    p.weight[3] = std::nan("");
    expect_invalid(p, "nan weight", "weight 3 ");
    p = good;
    p.weight[3] = -1;
    expect_invalid(p, "negative weight");
    p = good;
    p.velocity[5] = INFINITY;
    expect_invalid(p, "inf velocity", "velocity of point 1 is not finite");
    p = good;
    p.velocity[0] = std::nanf("");  // the first of the twelve lanes
    expect_invalid(p, "nan velocity", "velocity of point 0 is not finite");
    p = good;
    p.velocity[3 * 27 + 2] = -INFINITY;  // the last lane
    expect_invalid(p, "inf velocity in the last lane", "velocity of point 27 is not finite");
    p = RandomPoints(rng, 41, key, kCube, kVelocityBit);  // the last point outside the groups of four
    p.velocity[3 * 40 + 2] = -INFINITY;
    expect_invalid(p, "inf velocity in the last point", "velocity of point 40 is not finite");
    p = good;
    p.smoothing.pop_back();
    expect_invalid(p, "short column");
    p = RandomPoints(rng, 40, key, kCube, kAllColumns);
    p.prev_velocity[7] = std::nanf("");
    expect_invalid(p, "nan prev_velocity", "prev_velocity of point 2 is not finite");
    p = RandomPoints(rng, 40, key, kCube, kAllColumns);
    p.next_velocity.pop_back();
    expect_invalid(p, "short next_velocity");
    p = good;
    p.smoothing[0] = std::nan("");
    expect_invalid(p, "nan smoothing");
  }
}

}  // namespace
}  // namespace octocosm
