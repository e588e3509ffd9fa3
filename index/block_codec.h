// Block codec: the points of one octree node <-> the bytes of one block.
//
// A block is a header, a column directory and the columns, each column
// checksummed on its own, so that a reader can fetch the header and then only
// the columns it needs (ranged reads) and still verify every byte it uses.
// All integers are little endian; f32/f64 are IEEE-754 bit patterns stored as
// u32/u64. XXH3-64 is XXH3_64bits from libxxhash (seed 0).
//
// Block layout, version 1 (offsets in bytes from the start of the block):
//
//   fixed header (72 bytes)
//     0  u32  magic 0x4B42434F ("OCBK" in file order)
//     4  u16  version = 1
//     6  u16  header_size = 80 + 56 * column_count (fixed header + directory + header checksum)
//     8  u64  block_size: total bytes of the block
//    16  u64  node key (index/morton.h); must be the key the block is read as
//    24  u32  point count n
//    28  u16  column count c (1..16)
//    30  u16  flags = 0 (reserved)
//    32  9 x u32 octant offsets: points of child octant o are [off[o], off[o+1]);
//             off[0] = 0, non-decreasing, off[8] = n
//    68  u32  reserved = 0
//   column directory: c entries of 56 bytes, at 72 + 56 * i
//     0  u8   column id (table below); each id at most once
//     1  u8   encoding: 1, or for the id column 1 or 2 (table below)
//     2  u16  reserved = 0
//     4  u32  reserved = 0
//     8  u64  offset of the column's bytes from the start of the block
//    16  u64  length of the column's bytes
//    24  u64  XXH3-64 of the column's bytes
//    32  24 bytes of decode parameters (table below; unused bytes are 0)
//   header checksum: u64 XXH3-64 of bytes [0, header_size - 8), at header_size - 8
//   columns: in directory order, contiguous: the first starts at header_size,
//            each starts where the previous ends, the last ends at block_size.
//
// Columns (n = point count; s = node edge, o = node lower corner, both from
// the dataset cube and the node key, see index/cube.h):
//   id name          bytes   required  encoding / parameters
//   1  position      6n      yes       3 x u16 per point (x,y,z). q = the point's coordinate on
//                                      the 2^(L+16) grid of the cube minus 65536 * cell, i.e.
//                                      floor((x - o) / s * 65536) clamped to [0, 65535]; decoded
//                                      as o + (q + 0.5) * s / 65536, so |error| <= s / 131072 per
//                                      axis (half a quantum) and the decoded point is in the node
//                                      cube. The top bit of q on each axis is the child octant, and
//                                      must agree with the octant offsets. No parameters.
//   2  weight        4n      yes       u32 integer units per point summing exactly to K (0 if n = 0);
//                                      weight = units * unit. Params: f64 unit, u64 K. The writer
//                                      uses K = 2^32 - 2^20 and unit = (sum of weights) / K and
//                                      chooses the integers by the largest-remainder method, so the
//                                      decoded weights sum to the node mass to a few ulps and each
//                                      is within one unit (2.3e-10 of the node mass) of its value.
//   3  smoothing     2n      yes       u16 code per point: h = s * 2^(log2_min + code / per_octave).
//                                      Params: f32 log2_min, f32 per_octave. The writer uses
//                                      log2_min = -24 and per_octave = 2048 (h from s * 2^-24 to
//                                      s * 2^8), a relative precision of 2^(1/4096) - 1 = 1.7e-4.
//   4  velocity      6n      no        3 x u16 per point; v = min + q * (max - min) / 65535 per
//                                      component. Params: f32 min[3], f32 max[3] (min <= max,
//                                      finite). |error| <= (max - min) / 131070.
//   5  id            8n/4n   no        encoding 1: u64 per point, 8n bytes. Encoding 2: u32 per
//                                      point, id = base + value, 4n bytes; params: u64 base. The
//                                      writer uses encoding 2, with the block's smallest ID as
//                                      base, whenever the block's IDs span less than 2^32.
//   6  type          n       yes       u8 per point (GADGET particle type).
//   7  displacement  6n      no        like velocity: the minimal-image offset to the next epoch.
//   8  next_velocity 6n      no        like velocity: the particle's velocity at the next epoch.
//   9  prev_displacement 6n  no        like velocity: the minimal-image offset to the previous epoch.
//  10  prev_velocity 6n      no        like velocity: the particle's velocity at the previous epoch.
//  11  velocity_dispersion 2n no    u16 per point; sigma = min + q * (max - min) / 65535.
//                                      Params: f32 min, f32 max (finite, 0 <= min <= max).
//                                      |error| <= (max - min) / 131070. The one-dimensional rms
//                                      velocity dispersion of the particles a cluster stands for
//                                      (inner nodes whose points are clusters, in a dataset with
//                                      velocities; leaves and samples never carry it).
//  12  shape         6n      no        6 x u8 per point: the shape of a cluster's blob, its
//                                      covariance over trace / 3, entries xx, yy, zz (q / 85) and
//                                      xy, xz, yz ((q - 127) * 3 / 254, q <= 254), as
//                                      index/cluster_shape.h encodes it. No parameters. Inner
//                                      nodes whose points are clusters carry it; leaves and
//                                      samples never do (their blobs are round).
//  13  child_cluster 2m/4m   no        per point of the node's children (m of them: child octant 0's
//                                      points in its block's order, then octant 1's, ...), the
//                                      index (< n) of the cluster of this node that holds it.
//                                      Encoding 1: u16 per entry (n <= 65536); encoding 2: u32.
//                                      Params: u64 m. Every point of the node has at least one
//                                      entry, and the entries' clusters lie in non-decreasing
//                                      octants (a cluster lies in the child octant of its members).
//                                      Inner nodes whose points are clusters carry it.
//  14  refine_bound  6n      no        3 x u16 per point, log2 codes of R, a, r: component k is
//                                      2^(base[k] + code / 256), or 0 for code 0. Params: i32
//                                      base[3]. The writer stores each value rounded up to a
//                                      code (QuantizeRefineBounds), so a bound stays one. R: the
//                                      radius of a sphere about the point's decoded position
//                                      that holds the spheres of every cluster below it (its
//                                      members' and theirs); a and r: bounds, over the point
//                                      and every cluster below it, of its mass times its blob's
//                                      variance per axis (KernelVariance of its smoothing) and of
//                                      its mass. A parent's three exceed its clusters' by a
//                                      relative 2^-12 at least (before rounding up to a code).
//                                      What lets a renderer decide cluster by cluster, each on
//                                      its own, which to draw (docs/FORMAT.md section 4). Inner
//                                      nodes whose points are clusters carry it.
//
// Columns 8-14 were added to version 1 before any store left this project
// (docs/FORMAT.md section 4): a block without them is unchanged byte for byte.
// So were the id column's encoding 2 and the child_cluster column's: a reader
// from before reports such a block as corrupt ("unknown encoding"); blocks
// with encoding 1 read as ever.
//
// Decoding is safe for untrusted bytes: every offset, length, count and
// parameter is checked, and any mismatch throws Error::Corruption naming the
// caller's `where` (e.g. file and block key), the column and what was wrong.
// A version other than 1 throws Error::NotSupported.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "index/cube.h"
#include "index/morton.h"
#include "index/node_points.h"
#include "storage/block_source.h"

namespace octocosm {

enum class ColumnId : std::uint8_t {
  kPosition = 1,
  kWeight = 2,
  kSmoothing = 3,
  kVelocity = 4,
  kId = 5,
  kType = 6,
  kDisplacement = 7,
  kNextVelocity = 8,
  kPrevDisplacement = 9,
  kPrevVelocity = 10,
  kVelocityDispersion = 11,
  kShape = 12,
  kChildCluster = 13,
  kRefineBound = 14,
};

// The block column of each vector column (index/particle_chunk.h), indexed by VectorColumn.
inline constexpr std::array<ColumnId, kVectorColumnCount> kVectorColumnIds = {
    ColumnId::kVelocity, ColumnId::kDisplacement, ColumnId::kNextVelocity, ColumnId::kPrevDisplacement,
    ColumnId::kPrevVelocity};

// A set of columns, one bit per ColumnId.
using ColumnSet = std::uint32_t;
constexpr ColumnSet ColumnBit(ColumnId id) { return ColumnSet{1} << static_cast<unsigned>(id); }
inline constexpr ColumnSet kAllColumns = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                                         ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kVelocity) |
                                         ColumnBit(ColumnId::kId) | ColumnBit(ColumnId::kType) |
                                         ColumnBit(ColumnId::kDisplacement) | ColumnBit(ColumnId::kNextVelocity) |
                                         ColumnBit(ColumnId::kPrevDisplacement) | ColumnBit(ColumnId::kPrevVelocity) |
                                         ColumnBit(ColumnId::kVelocityDispersion) | ColumnBit(ColumnId::kShape);
// The columns that tie an inner node's clusters to its children's points for
// a level of detail refined cluster by cluster: not attributes of a point that
// a query returns (kAllColumns leaves them out).
inline constexpr ColumnSet kClusterLinkColumns = ColumnBit(ColumnId::kChildCluster) | ColumnBit(ColumnId::kRefineBound);

// Every column id, in the order blocks store them.
inline constexpr std::array<ColumnId, 14> kColumnIds = {
    ColumnId::kPosition,         ColumnId::kWeight,       ColumnId::kSmoothing,           ColumnId::kVelocity,
    ColumnId::kId,               ColumnId::kType,         ColumnId::kDisplacement,        ColumnId::kNextVelocity,
    ColumnId::kPrevDisplacement, ColumnId::kPrevVelocity, ColumnId::kVelocityDispersion, ColumnId::kShape,
    ColumnId::kChildCluster,     ColumnId::kRefineBound};

const char* ColumnName(ColumnId id);
// The names of the columns in `columns`, comma-separated, in block order.
std::string ColumnNames(ColumnSet columns);

// The vector column of `points` (NodePoints, const or not) that block column
// `id` holds, or nullptr when `id` is not a vector column.
template <typename Points>
auto VectorColumnOf(Points& points, ColumnId id) -> decltype(&points.velocity) {
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (kVectorColumnIds[v] == id) return VectorColumns(points)[v];
  }
  return nullptr;
}

inline constexpr std::uint32_t kBlockMagic = 0x4B42434F;
inline constexpr std::uint16_t kBlockVersion = 1;
inline constexpr std::size_t kBlockFixedHeaderSize = 72;
inline constexpr std::size_t kBlockDirectoryEntrySize = 56;
inline constexpr std::size_t kBlockMaxColumns = 16;
inline constexpr std::size_t kBlockMaxHeaderSize = kBlockFixedHeaderSize + kBlockDirectoryEntrySize * kBlockMaxColumns + 8;
// Column encodings (the directory's byte 1): kEncodingV1 for every column,
// kEncodingIdOffsets (u32 offsets from a u64 base) for the id column and
// kEncodingChildClusterU32 for the child_cluster column only.
inline constexpr std::uint8_t kEncodingV1 = 1;
inline constexpr std::uint8_t kEncodingIdOffsets = 2;
inline constexpr std::uint8_t kEncodingChildClusterU32 = 2;  // the child_cluster column's u32 entries
inline constexpr std::uint64_t kWeightTotalUnits = (std::uint64_t{1} << 32) - (std::uint64_t{1} << 20);
inline constexpr float kSmoothingLog2Min = -24;
inline constexpr float kSmoothingPerOctave = 2048;

// The smoothing length h of a node of edge node_size as its block stores
// it (the nearest code's length): what a reader decodes.
double StoredSmoothing(double h, double node_size);

// Rounds each value of a refine_bound column (3 per point, finite, >= 0) up
// to the nearest the column stores (a power of 2^(1/256), or 0): the values
// the block then holds exactly. A parent's bounds are computed from its
// clusters' bounds as stored. Throws Error::InvalidArgument on a value that
// is not finite and >= 0.
void QuantizeRefineBounds(std::vector<float>& bounds);

struct BlockColumn {
  ColumnId id{};
  std::uint8_t encoding = kEncodingV1;
  std::uint64_t offset = 0;  // from the start of the block
  std::uint64_t length = 0;
  std::uint64_t checksum = 0;
  std::array<std::uint8_t, 24> params{};
};

struct BlockHeader {
  NodeKey key;
  std::uint32_t point_count = 0;
  std::array<std::uint32_t, 9> octant_offsets{};
  std::size_t header_size = 0;
  std::uint64_t block_size = 0;
  std::vector<BlockColumn> columns;  // directory order

  // The directory entry of `id`, or nullptr when the block has no such column.
  const BlockColumn* Find(ColumnId id) const;
};

// Encodes `points` as the block of node `key`. Optional columns are written
// when non-empty. Throws Error::InvalidArgument when the points do not fit
// the contract: a column of the wrong length, a point outside the node cube,
// points not grouped by child octant as octant_offsets says (see
// OrderByOctant), a weight that is not finite and >= 0 (or all zero with
// points present), a non-finite value in a vector column, a velocity
// dispersion that is not finite and >= 0, or more than 2^32 - 1 points.
Bytes EncodeBlock(const NodePoints& points, NodeKey key, const Cube& cube);
// The same into `block`, whose memory is reused (an encoder that keeps one
// buffer neither zeroes nor first-touches a fresh block per node).
void EncodeBlock(const NodePoints& points, NodeKey key, const Cube& cube, Bytes& block);

// Reads the size of the header from the first kBlockFixedHeaderSize bytes of
// a block (or more), so that a ranged reader knows how much to fetch. Throws
// Error::Corruption on a short prefix, a bad magic or an impossible size.
std::size_t DecodeBlockHeaderSize(std::span<const std::uint8_t> prefix, const std::string& where);

// Parses and verifies the header and directory from a prefix of the block of
// at least header_size bytes (the whole block also works). `key` is the node
// the caller expects the block to hold.
BlockHeader DecodeBlockHeader(std::span<const std::uint8_t> prefix, NodeKey key, const std::string& where);

// Decodes one column from its bytes alone (bytes [offset, offset + length)
// of the block, as the header's directory says) into `out`, checking its
// checksum and contents. `out.octant_offsets` is set from the header.
void DecodeColumn(const BlockHeader& header, ColumnId id, std::span<const std::uint8_t> column_bytes,
                  const Cube& cube, const std::string& where, NodePoints& out);

struct DecodedBlock {
  BlockHeader header;  // header.point_count is the number of points, whichever columns were decoded
  NodePoints points;   // columns not decoded are empty
};

// Decodes the columns in `wanted` from a whole block. Wanted optional columns
// that the block lacks come back empty; a missing required column is corrupt.
// Columns not wanted are neither verified nor decoded.
DecodedBlock DecodeBlock(std::span<const std::uint8_t> block, ColumnSet wanted, NodeKey key, const Cube& cube,
                       const std::string& where);

// Checks that `bytes` are the column `column` describes: its length and its
// checksum. Throws Error::Corruption naming `where` and the column.
void VerifyColumnBytes(const BlockColumn& column, std::span<const std::uint8_t> bytes, const std::string& where);

// A block holding only the columns in `keep` of the block `header` describes:
// the same key, point count and octant offsets, and each kept column's bytes,
// parameters and checksum unchanged, so that it decodes and verifies like any
// block. What a reader caches when it needs only some columns (the renderer).
// column_bytes[i] holds the bytes of header.columns[i] when that column is
// kept (verified by the caller, e.g. VerifyColumnBytes); others are ignored.
// Throws Error::InvalidArgument when a kept column's bytes have the wrong length.
Bytes AssembleColumnSubset(const BlockHeader& header, ColumnSet keep,
                           std::span<const std::span<const std::uint8_t>> column_bytes);

}  // namespace octocosm
