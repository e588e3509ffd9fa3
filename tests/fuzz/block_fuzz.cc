// Fuzz target: the block codec's decoders (index/block_codec.h), which take
// bytes: DecodeBlockHeaderSize, DecodeBlockHeader, DecodeColumn, DecodeBlock,
// and a block rebuilt from a column subset (AssembleColumnSubset) decoded
// again. The input is a flag byte and the block: flag bit 0 seals the
// block's checksums (store_fuzz_util.h), bits 1-2 choose the dataset cube.
// The node key is the one the block names when that is a valid key, so that
// the checks behind the key comparison are reached.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "base/error.h"
#include "index/block_codec.h"
#include "index/cube.h"
#include "index/morton.h"
#include "storage/coding.h"
#include "tests/fuzz/fuzz_target.h"
#include "tests/fuzz/store_fuzz_util.h"

namespace octocosm::fuzz {
namespace {

const std::array<Cube, 4> kCubes = {Cube{{0, 0, 0}, 1, false}, Cube{{-50, -50, -50}, 100, true},
                                     Cube{{1e6, -3, 2}, 1e-3, false}, Cube{{0, 0, 0}, 65536, true}};

void DecodeEveryWay(std::span<const std::uint8_t> block, const Cube& cube) {
  const std::string where = "fuzz block";
  NodeKey key = NodeKey::Root();
  if (block.size() >= 24) {
    const NodeKey named = NodeKey::FromValue(GetU64(&block[16]));
    if (named.IsValid() && named.level() <= kMaxLevel) key = named;
  }
  try {
    const std::size_t header_size = DecodeBlockHeaderSize(block, where);
    Require(header_size <= kBlockMaxHeaderSize, "DecodeBlockHeaderSize exceeds the largest header");
    if (header_size > block.size()) return;
    const BlockHeader header = DecodeBlockHeader(block.first(header_size), key, where);
    NodePoints columns;
    std::vector<std::span<const std::uint8_t>> column_bytes;
    for (const BlockColumn& column : header.columns) {
      // The header alone cannot know the block's real length: a ranged reader
      // fetches a column where the header says, and fails there if it is past the end.
      if (column.offset > block.size() || column.length > block.size() - column.offset) return;
      column_bytes.push_back(block.subspan(column.offset, column.length));
      DecodeColumn(header, column.id, column_bytes.back(), cube, where, columns);
    }
    const DecodedBlock decoded = DecodeBlock(block, kAllColumns | kClusterLinkColumns, key, cube, where);
    Require(decoded.points.size() == decoded.header.point_count, "DecodeBlock's weights differ from its point count");
    Require(decoded.points.position.size() == 3 * decoded.header.point_count,
            "DecodeBlock's positions differ from its point count");
    const ColumnSet subset = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                             ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kType) |
                             ColumnBit(ColumnId::kVelocity);
    const Bytes assembled = AssembleColumnSubset(header, subset, column_bytes);
    DecodeBlock(assembled, subset, key, cube, where);
  } catch (const Error& e) {
    Refused(e);
  }
}

}  // namespace

std::vector<Seed> Seeds(const std::string&) {
  std::vector<Seed> seeds;
  auto add = [&](const std::string& name, int cube_index, const NodePoints& points, NodeKey key) {
    const Bytes block = EncodeBlock(points, key, kCubes[cube_index]);
    std::string bytes(1, static_cast<char>(1 | (cube_index << 1)));
    bytes.append(reinterpret_cast<const char*>(block.data()), block.size());
    seeds.push_back({name, bytes});
  };
  const NodeKey child = NodeKey::Root().Child(5);
  const NodeKey deep = child.Child(2).Child(7).Child(0);
  add("root-plain", 0, SeedPoints(NodeKey::Root(), kCubes[0], 9, 1, false, false), NodeKey::Root());
  add("child-velocity-cluster", 1, SeedPoints(child, kCubes[1], 12, 100, true, true), child);
  add("deep-wide-ids", 2, SeedPoints(deep, kCubes[2], 6, std::uint64_t{1} << 40, true, false), deep);
  {  // IDs spanning more than 2^32: the u64 encoding.
    NodePoints points = SeedPoints(child, kCubes[3], 4, 7, false, false);
    points.id.back() = ~std::uint64_t{0} - 3;
    add("child-u64-ids", 3, points, child);
  }
  add("empty", 0, SeedPoints(NodeKey::Root(), kCubes[0], 0, 1, false, false), NodeKey::Root());
  return seeds;
}

}  // namespace octocosm::fuzz

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::uint8_t flags = data[0];
  std::vector<std::uint8_t> block(data + 1, data + size);
  if (flags & 1) octocosm::fuzz::SealBlock(block);
  octocosm::fuzz::DecodeEveryWay(block, octocosm::fuzz::kCubes[(flags >> 1) & 3]);
  return 0;
}
