#include "render/gpu_block.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <utility>
#include <string>
#include <vector>

#include "base/error.h"
#include "storage/coding.h"

namespace octocosm {
namespace {

float ParamF32(const BlockColumn& c, int offset) { return std::bit_cast<float>(GetU32(c.params.data() + offset)); }
double ParamF64(const BlockColumn& c, int offset) { return std::bit_cast<double>(GetU64(c.params.data() + offset)); }

// The shader decodes q in [0, 65535] as min + q * step.
void SetRange(const BlockColumn& c, float (&range)[2][4]) {
  for (int a = 0; a < 3; ++a) {
    const float lo = ParamF32(c, 4 * a), hi = ParamF32(c, 12 + 4 * a);
    range[0][a] = lo;
    range[1][a] = (hi - lo) / 65535.0f;
  }
}

// How far each octant's blobs reach from their centres, in world units: the
// largest smoothing length there, times the root of the largest trace of a
// cluster's shape (its covariance over trace / 3, so its largest axis is at
// most the root of its trace times the round radius; index/cluster_shape.h).
std::array<double, 8> OctantReach(std::span<const std::uint8_t> bytes, const BlockHeader& header, const NodeCube& node) {
  std::span<const std::uint8_t> smoothing, shape;
  float log2_min = 0, per_octave = 1;
  for (const BlockColumn& c : header.columns) {  // their places checked by Upload
    const auto column = bytes.subspan(static_cast<std::size_t>(c.offset), static_cast<std::size_t>(c.length));
    if (c.id == ColumnId::kSmoothing) {
      smoothing = column;
      log2_min = ParamF32(c, 0);
      per_octave = ParamF32(c, 4);
    } else if (c.id == ColumnId::kShape) {
      shape = column;
    }
  }
  std::array<double, 8> reach{};
  const std::uint32_t n = header.point_count;
  if (smoothing.size() < 2 * std::size_t{n} || !(per_octave > 0)) return reach;
  const bool shaped = shape.size() >= 6 * std::size_t{n};
  for (int o = 0; o < 8; ++o) {
    const std::uint32_t end = std::min(header.octant_offsets[static_cast<std::size_t>(o) + 1], n);
    std::uint32_t largest_code = 0, largest_trace = 0;
    for (std::uint32_t i = std::min(header.octant_offsets[static_cast<std::size_t>(o)], end); i < end; ++i) {
      largest_code = std::max<std::uint32_t>(largest_code, GetU16(smoothing.data() + 2 * std::size_t{i}));
      if (shaped) {
        const std::uint8_t* q = shape.data() + 6 * std::size_t{i};
        largest_trace = std::max<std::uint32_t>(largest_trace, std::uint32_t{q[0]} + q[1] + q[2]);
      }
    }
    const double h = node.size * std::exp2(log2_min + static_cast<double>(largest_code) / per_octave);
    reach[static_cast<std::size_t>(o)] = h * std::sqrt(std::max(1.0, largest_trace / 85.0));
  }
  return reach;
}

// One function for a node's and its parent's: the cut compares a cluster's
// error in its own draw and in its children's, which must agree to the bit.
float NodeQuantum(const NodeCube& node) { return static_cast<float>(node.size / 65536.0); }

}  // namespace

GpuBlock GpuBlock::Upload(GpuBlockArena& arena, std::span<const std::uint8_t> bytes, const BlockHeader& header,
                          const NodeCube& node, const std::string& where, const ClusterCutUpload* cut) {
  GpuBlock block;
  block.point_count_ = header.point_count;
  block.octant_offsets_ = header.octant_offsets;
  block.node_ = node;

  GpuBlockParameters u{};
  for (auto& row : u.columns) {
    for (std::int32_t& c : row) c = -1;
  }
  u.node[0] = NodeQuantum(node);
  std::vector<GpuColumnBytes> columns;
  for (const BlockColumn& c : header.columns) {
    if (kClusterLinkColumns & ColumnBit(c.id)) continue;  // not drawn: the level of detail's, not a point's
    if (c.offset > bytes.size() || c.length > bytes.size() - c.offset) {
      throw Error::Corruption(where, std::string("column '") + ColumnName(c.id) + "' lies outside the block's " +
                                         std::to_string(bytes.size()) + " bytes");
    }
    columns.push_back({c.id, c.encoding, bytes.subspan(static_cast<std::size_t>(c.offset), static_cast<std::size_t>(c.length))});
    // The shader only asks whether a column is present (>= 0).
    constexpr std::int32_t kPresent = 0;
    block.columns_ |= ColumnBit(c.id);
    switch (c.id) {
      case ColumnId::kPosition: u.columns[0][0] = kPresent; break;
      case ColumnId::kWeight:
        u.columns[0][1] = kPresent;
        u.node[1] = static_cast<float>(ParamF64(c, 0));
        break;
      case ColumnId::kSmoothing:
        u.columns[0][2] = kPresent;
        u.node[2] = static_cast<float>(std::log2(node.size) + ParamF32(c, 0));
        u.node[3] = 1.0f / ParamF32(c, 4);
        break;
      case ColumnId::kType: u.columns[0][3] = kPresent; break;
      case ColumnId::kVelocity:
        u.columns[1][0] = kPresent;
        SetRange(c, u.ranges[0]);
        break;
      case ColumnId::kId:
        u.columns[1][1] = kPresent;
        if (c.encoding == kEncodingIdOffsets) {
          const std::uint64_t base = GetU64(c.params.data());
          u.id_base[0] = static_cast<std::uint32_t>(base);
          u.id_base[1] = static_cast<std::uint32_t>(base >> 32);
        }
        break;
      case ColumnId::kDisplacement:
        u.columns[1][2] = kPresent;
        SetRange(c, u.ranges[1]);
        break;
      case ColumnId::kNextVelocity:
        u.columns[1][3] = kPresent;
        SetRange(c, u.ranges[2]);
        break;
      case ColumnId::kPrevDisplacement:
        u.columns[2][0] = kPresent;
        SetRange(c, u.ranges[3]);
        break;
      case ColumnId::kPrevVelocity:
        u.columns[2][1] = kPresent;
        SetRange(c, u.ranges[4]);
        break;
      case ColumnId::kVelocityDispersion: {
        u.columns[2][2] = kPresent;
        const float lo = ParamF32(c, 0), hi = ParamF32(c, 4);
        u.dispersion[0] = lo;
        u.dispersion[1] = (hi - lo) / 65535.0f;
        break;
      }
      case ColumnId::kShape: u.columns[2][3] = kPresent; break;
      case ColumnId::kChildCluster:
      case ColumnId::kRefineBound: break;  // skipped above
    }
  }
  block.links_ = ClusterLinks::FromBlock(bytes, header, node, where);
  std::vector<ClusterCutEntry> cut_entries;
  if (cut != nullptr) {
    cut_entries.resize(header.point_count);  // zeros: a leaf's particles have no bounds
    if (block.links_) block.links_->SetOwnBounds(cut_entries);
    if (cut->parent != nullptr) cut->parent->GatherParents(cut->first_entry, cut_entries, where);
    block.has_cut_ = true;
    block.has_parent_ = cut->parent != nullptr;
    block.parent_node_ = cut->parent != nullptr ? cut->parent_node : node;
    if (block.links_) {
      for (int k = 0; k < 3; ++k) u.refine[0][k] = static_cast<float>(block.links_->bases()[static_cast<std::size_t>(k)]);
    }
    u.refine[0][3] = NodeQuantum(node);
    if (cut->parent != nullptr) {
      for (int k = 0; k < 3; ++k) u.refine[1][k] = static_cast<float>(cut->parent->bases()[static_cast<std::size_t>(k)]);
    }
    u.refine[1][3] = NodeQuantum(block.parent_node_);
    columns.push_back({ColumnId::kRefineBound, kEncodingV1,
                       std::span(reinterpret_cast<const std::uint8_t*>(cut_entries.data()),
                                 cut_entries.size() * sizeof(ClusterCutEntry))});
  }
  const ColumnSet required = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                             ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kType);
  if ((block.columns_ & required) != required) {
    throw Error::Corruption(where, "a block sent to the GPU lacks positions, weights, smoothing lengths or types");
  }
  try {
    block.placement_ = arena.Place(columns, header.point_count, u);
  } catch (const Error& e) {
    if (e.kind() == ErrorKind::kInvalidArgument) throw Error::Corruption(where, e.what());
    throw;
  }
  block.arena_ = &arena;
  block.octant_reach_ = OctantReach(bytes, header, node);
  for (const GpuColumnBytes& c : columns) block.gpu_bytes_ += c.bytes.size();
  block.gpu_bytes_ += sizeof u;
  return block;
}

GpuBlock::GpuBlock(GpuBlock&& other) noexcept
    : arena_(std::exchange(other.arena_, nullptr)),
      placement_(other.placement_),
      point_count_(other.point_count_),
      octant_offsets_(other.octant_offsets_),
      octant_reach_(other.octant_reach_),
      node_(other.node_),
      columns_(other.columns_),
      gpu_bytes_(other.gpu_bytes_),
      links_(std::move(other.links_)),
      has_cut_(other.has_cut_),
      has_parent_(other.has_parent_),
      parent_node_(other.parent_node_) {}

GpuBlock& GpuBlock::operator=(GpuBlock&& other) noexcept {
  if (this != &other) {
    if (arena_ != nullptr) arena_->Release(placement_);
    arena_ = std::exchange(other.arena_, nullptr);
    placement_ = other.placement_;
    point_count_ = other.point_count_;
    octant_offsets_ = other.octant_offsets_;
    octant_reach_ = other.octant_reach_;
    node_ = other.node_;
    columns_ = other.columns_;
    gpu_bytes_ = other.gpu_bytes_;
    links_ = std::move(other.links_);
    has_cut_ = other.has_cut_;
    has_parent_ = other.has_parent_;
    parent_node_ = other.parent_node_;
  }
  return *this;
}

GpuBlock::~GpuBlock() {
  if (arena_ != nullptr) arena_->Release(placement_);
}

}  // namespace octocosm
