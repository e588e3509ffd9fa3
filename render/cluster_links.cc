#include "render/cluster_links.h"

#include <algorithm>
#include <cmath>

#include "base/error.h"
#include "index/node_points.h"
#include "storage/coding.h"

namespace octocosm {
namespace {

std::span<const std::uint8_t> ColumnBytes(std::span<const std::uint8_t> bytes, const BlockColumn& c,
                                          const std::string& where) {
  if (c.offset > bytes.size() || c.length > bytes.size() - c.offset) {
    throw Error::Corruption(where, std::string("column '") + ColumnName(c.id) + "' lies outside the block's " +
                                       std::to_string(bytes.size()) + " bytes");
  }
  return bytes.subspan(static_cast<std::size_t>(c.offset), static_cast<std::size_t>(c.length));
}

}  // namespace

std::unique_ptr<const ClusterLinks> ClusterLinks::FromBlock(std::span<const std::uint8_t> bytes,
                                                            const BlockHeader& header, const NodeCube& node,
                                                            const std::string& where) {
  const BlockColumn* links = header.Find(ColumnId::kChildCluster);
  const BlockColumn* bounds = header.Find(ColumnId::kRefineBound);
  const BlockColumn* position = header.Find(ColumnId::kPosition);
  if (links == nullptr && bounds == nullptr) return nullptr;
  if (links == nullptr || bounds == nullptr || position == nullptr) {
    throw Error::Corruption(where, "a block carries one of child_cluster and refine_bound without the other, or "
                                   "without positions");
  }
  // The codec checks both columns (checksums, entries, codes in range).
  NodePoints decoded;
  DecodeColumn(header, ColumnId::kChildCluster, ColumnBytes(bytes, *links, where), Cube{}, where, decoded);
  DecodeColumn(header, ColumnId::kRefineBound, ColumnBytes(bytes, *bounds, where), Cube{}, where, decoded);
  const std::span<const std::uint8_t> position_bytes = ColumnBytes(bytes, *position, where);
  const std::size_t n = header.point_count;
  if (position_bytes.size() < 6 * n) {
    throw Error::Corruption(where, "the position column holds fewer bytes than the block's points take");
  }
  std::unique_ptr<ClusterLinks> l(new ClusterLinks());
  l->child_cluster_ = std::move(decoded.child_cluster);
  const std::span<const std::uint8_t> code_bytes = ColumnBytes(bytes, *bounds, where);
  l->codes_.resize(3 * n);
  l->position_.resize(3 * n);
  for (std::size_t i = 0; i < 3 * n; ++i) {
    l->codes_[i] = GetU16(code_bytes.data() + 2 * i);
    l->position_[i] = GetU16(position_bytes.data() + 2 * i);
  }
  for (int k = 0; k < 3; ++k) l->bases_[static_cast<std::size_t>(k)] = static_cast<std::int32_t>(GetU32(bounds->params.data() + 4 * k));

  // Each cluster's sphere about its position, and its bounds.
  const double quantum = node.size / 65536.0;
  std::vector<OctantRefineBound> clusters(n);
  for (std::size_t i = 0; i < n; ++i) {
    OctantRefineBound& cluster = clusters[i];
    for (std::size_t a = 0; a < 3; ++a) cluster.centre[a] = node.origin[a] + (l->position_[3 * i + a] + 0.5) * quantum;
    const float* v = decoded.refine_bound.data() + 3 * i;
    cluster.radius = v[0];
    cluster.mass_variance = v[1];
    cluster.mass = v[2];
  }
  l->bounds_ = NodeRefineBounds::Of(node, clusters, header.octant_offsets);
  return l;
}

void ClusterLinks::GatherParents(std::uint64_t first, std::span<ClusterCutEntry> out, const std::string& where) const {
  if (first > child_cluster_.size() || out.size() > child_cluster_.size() - first) {
    throw Error::Corruption(where, "the node holds " + std::to_string(out.size()) + " points from entry " +
                                       std::to_string(first) + " of its parent's links, which has " +
                                       std::to_string(child_cluster_.size()));
  }
  for (std::size_t i = 0; i < out.size(); ++i) {
    const std::size_t c = child_cluster_[first + i];  // < cluster_count(): checked by the codec
    for (std::size_t k = 0; k < 3; ++k) {
      out[i].parent[k] = std::uint32_t{position_[3 * c + k]} | (std::uint32_t{codes_[3 * c + k]} << 16);
    }
  }
}

void ClusterLinks::SetOwnBounds(std::span<ClusterCutEntry> out) const {
  for (std::size_t i = 0; i < out.size() && i < cluster_count(); ++i) {
    for (std::size_t k = 0; k < 3; ++k) out[i].own[k] = codes_[3 * i + k];
  }
}

}  // namespace octocosm
