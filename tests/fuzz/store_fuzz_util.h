// Blocks and stores for the store fuzz targets (tests/fuzz): seed points,
// and "sealing", which recomputes the checksums of bytes the fuzzer changed.
//
// Every structure of a store carries a checksum (the manifest, the page-file
// header, each index page, each block and, inside a block, its header and
// each column), so almost every mutation would stop at the first checksum
// and the checks behind it would never run. A target therefore seals what it
// was given when the input's flag byte asks for it: the checksums then agree
// and the structural checks must catch the damage. Inputs without the flag
// exercise the checksum checks themselves.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "index/block_codec.h"
#include "index/cube.h"
#include "index/morton.h"
#include "index/node_points.h"
#include "storage/block_index_format.h"
#include "storage/checksum.h"
#include "storage/coding.h"
#include "storage/manifest.h"
#include "storage/page_file_format.h"

namespace octocosm::fuzz {

// `n` points spread over the cube of node `key`, ordered by octant as
// EncodeBlock wants them, with IDs from `first_id`; velocities when
// `velocity`, and a cluster's velocity dispersion, shape and links (two
// children's points a cluster, rounded bounds) when `cluster`.
inline NodePoints SeedPoints(NodeKey key, const Cube& cube, std::size_t n, std::uint64_t first_id, bool velocity,
                             bool cluster) {
  const NodeCube node = cube.NodeCubeOf(key);
  NodePoints points;
  for (std::size_t i = 0; i < n; ++i) {
    for (int axis = 0; axis < 3; ++axis) {
      const double t = static_cast<double>((i * 7 + static_cast<std::size_t>(axis) * 3) % 16) / 16 + 1.0 / 64;
      points.position.push_back(node.origin[axis] + t * node.size);
      if (velocity) points.velocity.push_back(static_cast<float>(i) - static_cast<float>(axis) * 2.5f);
    }
    points.weight.push_back(1.0 + static_cast<double>(i % 3));
    points.smoothing.push_back(node.size / (4.0 + static_cast<double>(i % 5)));
    points.id.push_back(first_id + i);
    points.type.push_back(static_cast<std::uint8_t>(i % 2));
    if (cluster) {
      points.velocity_dispersion.push_back(0.5f * static_cast<float>(i % 4));
      points.shape.insert(points.shape.end(), {85, 85, 85, 127, 127, 127});
    }
  }
  OrderByOctant(points, key, cube);
  if (cluster) {
    for (std::uint32_t c = 0; c < n; ++c) points.child_cluster.insert(points.child_cluster.end(), {c, c});
    for (std::size_t i = 0; i < 3 * n; ++i) points.refine_bound.push_back(static_cast<float>(node.size) * (1 + i % 5));
    QuantizeRefineBounds(points.refine_bound);
  }
  return points;
}

// Recomputes a block's column checksums (of the columns that lie inside it)
// and its header checksum, wherever its column count leaves a header that fits.
inline void SealBlock(std::span<std::uint8_t> block) {
  if (block.size() < kBlockFixedHeaderSize) return;
  const std::size_t columns = std::min<std::size_t>(GetU16(&block[28]), kBlockMaxColumns);
  const std::size_t header_size = kBlockFixedHeaderSize + kBlockDirectoryEntrySize * columns + 8;
  if (header_size > block.size()) return;
  for (std::size_t c = 0; c < columns; ++c) {
    std::uint8_t* entry = &block[kBlockFixedHeaderSize + kBlockDirectoryEntrySize * c];
    const std::uint64_t offset = GetU64(entry + 8);
    const std::uint64_t length = GetU64(entry + 16);
    if (offset <= block.size() && length <= block.size() - offset) {
      PutU64(entry + 24, Checksum64(block.subspan(offset, length)));
    }
  }
  PutU64(&block[header_size - 8], Checksum64(block.first(header_size - 8)));
}

// Recomputes every checksum of a page file that its header lets one find:
// each block a leaf entry points to inside the file (SealBlock, then the
// entry's block checksum), each index page, and the header.
inline void SealPageFile(std::span<std::uint8_t> file) {
  namespace off = header_offset;
  if (file.size() < kPageFileHeaderSize) return;
  const std::uint32_t page_size = GetU32(&file[off::kPageSize]);
  if (IsValidPageSize(page_size)) {
    const std::uint64_t pages_in_file = file.size() / page_size;
    const std::uint64_t first = GetU64(&file[off::kIndexFirstPage]);
    const std::uint64_t count = GetU64(&file[off::kIndexPageCount]);
    for (std::uint64_t p = first; p < pages_in_file && p - first < count; ++p) {
      const std::span<std::uint8_t> page = file.subspan(p * page_size, page_size);
      const bool leaf = page[4] == kLeafPageKind;
      const std::size_t entry_size = leaf ? kLeafEntrySize : kInteriorEntrySize;
      const std::size_t entries =
          std::min<std::size_t>(GetU32(&page[8]), (page_size - kIndexPageHeaderSize) / entry_size);
      for (std::size_t i = 0; leaf && i < entries; ++i) {
        std::uint8_t* entry = &page[kIndexPageHeaderSize + i * kLeafEntrySize];
        const std::uint64_t block_page = GetU64(entry + 8);
        const std::uint64_t length = GetU64(entry + 16);
        if (block_page < pages_in_file && length <= file.size() - block_page * page_size) {
          const std::span<std::uint8_t> block = file.subspan(block_page * page_size, length);
          SealBlock(block);
          PutU64(entry + 32, Checksum64(block));
        }
      }
      PutU64(&page[24], Checksum64(page.first(24), page.subspan(kIndexPageHeaderSize, entries * entry_size)));
    }
  }
  PutU64(&file[off::kChecksum], Checksum64(file.first(off::kChecksum)));
}

// Re-seals a manifest that parses as a JSON object; leaves other text alone.
inline void SealManifestText(std::string& text) {
  nlohmann::json manifest = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (!manifest.is_object()) return;
  SealManifest(manifest);
  text = manifest.dump();
}

}  // namespace octocosm::fuzz
