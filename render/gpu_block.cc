#include "render/gpu_block.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <optional>
#include <utility>
#include <string>
#include <vector>

#include "storage/coding.h"
#include "storage/error.h"

namespace octocosm {
namespace {

// Attribute locations of shaders/splat_vert.glsl.
enum Attribute : GLuint {
  kPositionAttribute = 0,
  kWeightAttribute,
  kSmoothingAttribute,
  kTypeAttribute,
  kVelocityAttribute,
  kIdAttribute,
  kDisplacementAttribute,
  kNextVelocityAttribute,
  kPrevDisplacementAttribute,
  kPrevVelocityAttribute,
  kVelocityDispersionAttribute,
  kShapeDiagonalAttribute,
  kShapeOffDiagonalAttribute,
};

// How a column is read as a vertex attribute.
struct AttributeFormat {
  GLuint location;
  GLint components;
  GLenum type;
  bool integer;  // glVertexArrayAttribIFormat (uint in the shader) or float
  GLsizei stride;
};

// The id column's attribute reads whole u64 IDs (encoding 1: two words, low
// first) or u32 offsets (encoding 2: the high word reads as 0), which the
// shader adds to the block's base.
std::optional<AttributeFormat> FormatOf(const BlockColumn& column) {
  switch (column.id) {
    case ColumnId::kPosition: return AttributeFormat{kPositionAttribute, 3, GL_UNSIGNED_SHORT, false, 6};
    case ColumnId::kWeight: return AttributeFormat{kWeightAttribute, 1, GL_UNSIGNED_INT, true, 4};
    case ColumnId::kSmoothing: return AttributeFormat{kSmoothingAttribute, 1, GL_UNSIGNED_SHORT, false, 2};
    case ColumnId::kType: return AttributeFormat{kTypeAttribute, 1, GL_UNSIGNED_BYTE, true, 1};
    case ColumnId::kVelocity: return AttributeFormat{kVelocityAttribute, 3, GL_UNSIGNED_SHORT, false, 6};
    case ColumnId::kId:
      return column.encoding == kEncodingIdOffsets ? AttributeFormat{kIdAttribute, 1, GL_UNSIGNED_INT, true, 4}
                                  : AttributeFormat{kIdAttribute, 2, GL_UNSIGNED_INT, true, 8};
    case ColumnId::kDisplacement: return AttributeFormat{kDisplacementAttribute, 3, GL_UNSIGNED_SHORT, false, 6};
    case ColumnId::kNextVelocity: return AttributeFormat{kNextVelocityAttribute, 3, GL_UNSIGNED_SHORT, false, 6};
    case ColumnId::kPrevDisplacement: return AttributeFormat{kPrevDisplacementAttribute, 3, GL_UNSIGNED_SHORT, false, 6};
    case ColumnId::kPrevVelocity: return AttributeFormat{kPrevVelocityAttribute, 3, GL_UNSIGNED_SHORT, false, 6};
    case ColumnId::kVelocityDispersion: return AttributeFormat{kVelocityDispersionAttribute, 1, GL_UNSIGNED_SHORT, false, 2};
    case ColumnId::kShape: return std::nullopt;  // two attributes: see ShapeFormats
  }
  return std::nullopt;
}

// The shape column's six bytes a point as two attributes: the diagonal
// codes at offset 0, the off-diagonal ones at offset 3.
constexpr AttributeFormat kShapeFormats[2] = {{kShapeDiagonalAttribute, 3, GL_UNSIGNED_BYTE, false, 6},
                                              {kShapeOffDiagonalAttribute, 3, GL_UNSIGNED_BYTE, false, 6}};

// The uniform block "Block" of shaders/splat_vert.glsl, std140.
struct BlockUniforms {
  float node[4];
  std::int32_t columns[3][4];
  float ranges[5][2][4];  // velocity, displacement, next_velocity, prev_displacement, prev_velocity: min, step
  std::uint32_t id_base[4];  // the id column's base (encoding 2), low word first; 0 for u64 IDs
  float dispersion[4];       // the velocity dispersion column's minimum and step
};
static_assert(sizeof(BlockUniforms) == 256);

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

}  // namespace

GpuBlock GpuBlock::Upload(std::span<const std::uint8_t> bytes, const BlockHeader& header, const NodeCube& node,
                          const std::string& where) {
  GpuBlock block;
  block.point_count_ = header.point_count;
  block.octant_offsets_ = header.octant_offsets;
  block.node_ = node;

  BlockUniforms u{};
  for (auto& row : u.columns) {
    for (std::int32_t& c : row) c = -1;
  }
  u.node[0] = static_cast<float>(node.size / 65536.0);

  // Columns at 16-byte boundaries.
  std::size_t total = 0;
  for (const BlockColumn& c : header.columns) total += (c.length + 15) / 16 * 16;
  std::vector<std::uint8_t> staging(total, 0);
  std::vector<std::pair<const BlockColumn*, std::size_t>> offsets;  // where each column landed
  std::size_t at = 0;
  for (const BlockColumn& c : header.columns) {
    if (c.offset > bytes.size() || c.length > bytes.size() - c.offset) {
      throw Error::Corruption(where, std::string("column '") + ColumnName(c.id) + "' lies outside the block's " +
                                         std::to_string(bytes.size()) + " bytes");
    }
    if (c.length > 0) std::memcpy(staging.data() + at, bytes.data() + c.offset, static_cast<std::size_t>(c.length));
    // The shader only asks whether a column is present (>= 0).
    constexpr std::int32_t kPresent = 0;
    block.columns_ |= ColumnBit(c.id);
    offsets.emplace_back(&c, at);
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
      default: break;  // columns the shader does not read
    }
    at += (c.length + 15) / 16 * 16;
  }
  const ColumnSet required = ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                             ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kType);
  if ((block.columns_ & required) != required) {
    throw Error::Corruption(where, "a block sent to the GPU lacks positions, weights, smoothing lengths or types");
  }
  block.buffer_ = MakeGlBuffer(at, staging.data(), 0);
  block.parameters_ = MakeGlBuffer(sizeof u, &u, 0);
  GLuint vao = 0;
  glCreateVertexArrays(1, &vao);
  block.vertex_array_ = GlVertexArray(vao);
  const auto bind = [&](const AttributeFormat& f, std::size_t offset) {
    glVertexArrayVertexBuffer(vao, f.location, block.buffer_.get(), static_cast<GLintptr>(offset), f.stride);
    if (f.integer) {
      glVertexArrayAttribIFormat(vao, f.location, f.components, f.type, 0);
    } else {
      glVertexArrayAttribFormat(vao, f.location, f.components, f.type, GL_FALSE, 0);
    }
    glVertexArrayAttribBinding(vao, f.location, f.location);
    glEnableVertexArrayAttrib(vao, f.location);
  };
  for (const auto& [column, offset] : offsets) {
    if (column->id == ColumnId::kShape) {
      bind(kShapeFormats[0], offset);
      bind(kShapeFormats[1], offset + 3);
    } else if (const std::optional<AttributeFormat> f = FormatOf(*column)) {
      bind(*f, offset);
    }  // else a column the renderer does not draw with
  }
  CheckGlError("uploading a block");
  block.gpu_bytes_ = at + sizeof u;
  return block;
}

}  // namespace octocosm
