// One point of a block -> one blob (render/splat_kernel.h), shared by both
// ways of drawing: the raster path (splat_vert.glsl: points fetched as vertex
// attributes, blobs drawn as point sprites) and the compute path
// (splat_comp.glsl: points read from the same column buffers as storage
// buffers, blobs added pixel by pixel with atomics). The block's columns are
// on the GPU as stored (index/block_codec.h) and decoded here. Positions are
// relative to the camera, so floats keep their precision near it however far
// the data lie from the origin.
//
// In a periodic box, a point moved between epochs past a face of the box is
// drawn at its image inside the box, near the opposite face. Which image is
// decided on its position relative to its node's corner (small numbers: the
// box's faces relative to the corner come from the CPU, subtracted in
// double), and the image is drawn from a corner the CPU moved by one box
// length, also in double: no float ever holds the difference of two large
// coordinates.

layout(std140, binding = 0) uniform Frame {
  vec4 u_right;     // camera basis (xyz)
  vec4 u_up;
  vec4 u_forward;
  vec4 u_viewport;  // image width, height (pixels), guard margin (pixels), focal length (pixels)
  vec4 u_limits;    // near, far, largest blob radius, 1 / mass unit
  ivec4 u_modes;    // colour mode, interpolation (0 none, 1 linear, 2 Hermite), highlight (0 none, 1 selected IDs, 2 every point, alone), copy direction (+1 / -1)
  vec4 u_time;      // t in [0, 1], weight of this copy, Hermite velocity scale, unused
  ivec4 u_wrap;     // 1: moved points are wrapped into the periodic box (the draw's box_*), 0: not; unused x 3
  vec4 u_cut;       // the cluster cut: threshold tau (mass), (half a pixel / focal length)^2, 1: count the points it takes, unused
};

// The points the cluster cut takes that are drawn, counted where u_cut.z is 1.
layout(binding = 0, offset = 0) uniform atomic_uint cut_points;

// A block's decode parameters (render/gpu_block_arena.h, GpuBlockParameters).
struct BlockParams {
  vec4 node;        // quantum (node edge / 65536), weight unit, log2 of the smallest smoothing, 1 / codes per octave
  ivec4 columns0;   // present (>= 0) or absent (-1): position, weight, smoothing, type
  ivec4 columns1;   // velocity, id, displacement, next_velocity
  ivec4 columns2;   // prev_displacement, prev_velocity, velocity_dispersion, shape
  vec4 velocity[2];           // minimum, step ((max - min) / 65535)
  vec4 displacement[2];
  vec4 next_velocity[2];
  vec4 prev_displacement[2];
  vec4 prev_velocity[2];
  uvec4 id_base;    // added to the id column: its base (u32 offsets), 0 for whole u64 IDs; low word first
  vec4 dispersion;  // velocity dispersion: minimum, step
  vec4 refine[2];   // the cluster cut: the bases of the block's bound codes, its quantum; its parent's
};
layout(std430, binding = 3) readonly buffer Blocks { BlockParams blocks[]; };

// One draw of a block's points (render/splat_renderer.h): its node's corner
// minus the camera position, in double on the CPU before the float, so that
// the precision that matters is near the camera. With u_wrap.x: the
// periodic box relative to the node's corner, [low, high) per axis, and the
// node's corner one box length lower (for points past the upper face) and
// higher (for points below the lower face), minus the camera.
struct DrawParams {
  vec4 origin;
  vec4 box_low;
  vec4 box_high;
  vec4 origin_below;
  vec4 origin_above;
  uvec4 block;  // x: the block's slot in Blocks; compute path: y first point in its pool, z count, w points before it in its dispatch
  vec4 parent_origin;  // the cluster cut: the parent node's corner minus the camera
  uvec4 cut;    // x: the draw's part in the cluster cut (kCut*)
};
layout(std430, binding = 4) readonly buffer Draws { DrawParams draws[]; };

// A draw's part in the cluster cut (render/splat_renderer.h, CutRole).
const uint kCutApplies = 1u;     // the points are drawn only where the cut takes them
const uint kCutFinal = 2u;       // their own error is not asked: nothing below them is drawn
const uint kCutHasParent = 4u;   // their parent's error is asked (all but the root)

layout(std430, binding = 1) readonly buffer Selection {
  uint selection_mask;   // slots - 1 (slots a power of two)
  uint selection_count;
  uint selection_pad0;
  uint selection_pad1;
  uvec2 selection_slots[];  // (low, high) words of a selected ID; (~0, ~0) empty
};

// A point as stored: u16 x 3 positions and ranged vectors (as floats
// 0..65535), u32 weight units, u16 smoothing codes, u8 types, u64 IDs (as
// two words, low first) or u32 ID offsets (the high word 0). Absent columns
// read as zero and are not used. A shape (index/cluster_shape.h) is six byte
// codes, as two triples.
struct Point {
  vec3 position;
  uint weight;
  float smoothing;
  uint type;
  vec3 velocity;
  uvec2 id;
  vec3 displacement;
  vec3 next_velocity;
  vec3 prev_displacement;
  vec3 prev_velocity;
  float velocity_dispersion;
  vec3 shape_diagonal;      // xx, yy, zz codes
  vec3 shape_off_diagonal;  // xy, xz, yz codes
  vec3 own_bound;           // the cluster cut: its bound codes (R, a, r; 0 for a particle)
  uvec3 parent;             // its parent cluster's position code | bound code << 16, per axis / bound
  uint draw;                // its draw's index in Draws
};

// A blob ready to add: its centre in the accumulation buffer's pixels (guard
// margin included), its footprint (a pixel offset d is at q^2 = conic.x dx^2
// + 2 conic.y dx dy + conic.z dy^2), its larger radius, and its amplitude
// times (1, a, a^2, selected).
struct Blob {
  vec2 center;
  vec3 conic;
  float major;
  vec4 value;
};

// The point's draw and block: fields read where used, not whole structs
// (a per-point copy of 352 bytes costs a software rasterizer dearly).
#define this_draw draws[pt.draw]
#define this_block blocks[draws[pt.draw].block.x]
#define b_node this_block.node
#define b_columns0 this_block.columns0
#define b_columns1 this_block.columns1
#define b_columns2 this_block.columns2
#define b_velocity this_block.velocity
#define b_displacement this_block.displacement
#define b_next_velocity this_block.next_velocity
#define b_prev_displacement this_block.prev_displacement
#define b_prev_velocity this_block.prev_velocity
#define b_id_base this_block.id_base
#define b_dispersion this_block.dispersion

vec3 Ranged(vec3 code, vec4 range[2]) { return range[0].xyz + code * range[1].xyz; }

// The lowbias32 integer hash; the same as SelectionSet's on the CPU.
uint Mix32(uint x) {
  x ^= x >> 16u;
  x *= 0x7feb352du;
  x ^= x >> 15u;
  x *= 0x846ca68bu;
  x ^= x >> 16u;
  return x;
}

// The point's 64-bit ID, low word first: the stored value plus the block's
// base, with the carry.
uvec2 ParticleId(Point pt) {
  uint low = pt.id.x + b_id_base.x;
  uint carry = low < b_id_base.x ? 1u : 0u;
  return uvec2(low, pt.id.y + b_id_base.y + carry);
}

bool IsSelected(uvec2 id) {
  uint slot = Mix32(id.x ^ Mix32(id.y)) & selection_mask;
  for (uint probe = 0u; probe <= selection_mask; ++probe) {
    uvec2 s = selection_slots[slot];
    if (s == id) return true;
    if (s == uvec2(0xFFFFFFFFu)) return false;
    slot = (slot + 1u) & selection_mask;
  }
  return false;
}

// The kernel summed over the pixel centres of the footprint, which lies
// within `extent` pixels of c.
float PixelSum(vec2 c, vec3 conic, float extent) {
  float sum = 0.0;
  int i0 = int(ceil(c.x - extent - 0.5)), i1 = int(floor(c.x + extent - 0.5));
  int j0 = int(ceil(c.y - extent - 0.5)), j1 = int(floor(c.y + extent - 0.5));
  for (int j = j0; j <= j1; ++j) {
    float dy = float(j) + 0.5 - c.y;
    for (int i = i0; i <= i1; ++i) {
      float dx = float(i) + 0.5 - c.x;
      sum += CubicKernel(FootprintDistance(conic, vec2(dx, dy)));
    }
  }
  return sum;
}

// The footprint of a blob of `scale` pixels (its round radius) and 3-D shape
// S: the ellipse of S's projection onto the image plane, S restricted to the
// camera's right and up axes (the same local approximation as the round
// blob's radius h * focal / depth), scaled by scale^2. Its two radii are held
// between 1 pixel and the largest blob radius, as a round blob's radius is.
// Returns the conic (the clamped matrix's inverse) and the two radii.
void Footprint(Point pt, float scale, out vec3 conic, out float major, out float minor) {
  vec3 m = vec3(scale * scale, 0.0, scale * scale);  // xx, xy, yy in pixels^2
  if (b_columns2.w >= 0) {
    vec3 d = pt.shape_diagonal / 85.0;
    vec3 o = (pt.shape_off_diagonal - 127.0) * (3.0 / 254.0);
    mat3 shape = mat3(d.x, o.x, o.y, o.x, d.y, o.z, o.y, o.z, d.z);
    vec3 r = shape * u_right.xyz, u = shape * u_up.xyz;
    m = scale * scale * vec3(dot(u_right.xyz, r), dot(u_right.xyz, u), dot(u_up.xyz, u));
  }
  float mean = 0.5 * (m.x + m.z), half_difference = 0.5 * (m.x - m.z);
  float root = sqrt(half_difference * half_difference + m.y * m.y);
  // The major axis, computed without cancellation; any axis for a circle.
  vec2 axis = half_difference >= 0.0 ? vec2(half_difference + root, m.y) : vec2(m.y, root - half_difference);
  axis = dot(axis, axis) > 0.0 ? normalize(axis) : vec2(1.0, 0.0);
  float limit = u_limits.z * u_limits.z;
  float l1 = clamp(mean + root, 1.0, limit), l2 = clamp(mean - root, 1.0, limit);
  vec2 other = vec2(-axis.y, axis.x);
  conic = vec3(axis.x * axis.x, axis.x * axis.y, axis.y * axis.y) / l1 +
          vec3(other.x * other.x, other.x * other.y, other.y * other.y) / l2;
  major = sqrt(l1);
  minor = sqrt(l2);
}

// A cluster's error bound E = s / sqrt(1 + s / r), s = a / (q D^2), seen from
// the camera (docs/FORMAT.md section 4), from its position and bound codes,
// its block's quantum and bases, and its node's corner minus the camera. A cluster's draw and its children's
// evaluate it from the same codes and floats, precisely (no fused or
// reordered operations), so both find the same E and each particle is drawn
// once.
float ClusterError(vec3 code, float quantum, vec3 origin, vec3 bound, vec3 base) {
  // code / 256 and its sum with an integer base are exact in float.
  precise vec3 value = exp2(base + bound / 256.0);
  value = mix(value, vec3(0.0), equal(bound, vec3(0.0)));
  if (!(value.y > 0.0 && value.z > 0.0)) return 0.0;
  precise vec3 x = (code + 0.5) * quantum + origin;
  precise float gap = max(sqrt(dot(x, x)) - value.x, 0.0);
  // At the sphere, or so near that the spread leaves the float range: infinite.
  float infinity = uintBitsToFloat(0x7F800000u);
  if (!(gap > 0.0)) return infinity;
  precise float spread = value.y / (u_cut.y * gap * gap);
  if (isinf(spread)) return infinity;
  precise float error = spread / sqrt(1.0 + spread / value.z);
  return error;
}

// Whether the cluster cut takes the point: its own error at most tau (not
// asked where nothing below it is drawn), its parent's above tau (where it
// has a parent).
bool InCut(Point pt) {
  uint flags = this_draw.cut.x;
  if ((flags & kCutApplies) == 0u) return true;
  float tau = u_cut.x;
  if ((flags & kCutFinal) == 0u &&
      ClusterError(pt.position, this_block.refine[0].w, this_draw.origin.xyz, pt.own_bound, this_block.refine[0].xyz) > tau) {
    return false;
  }
  if ((flags & kCutHasParent) != 0u) {
    vec3 code = vec3(pt.parent & 0xFFFFu), bound = vec3(pt.parent >> 16u);
    if (!(ClusterError(code, this_block.refine[1].w, this_draw.parent_origin.xyz, bound, this_block.refine[1].xyz) > tau)) {
      return false;
    }
  }
  return true;
}

// The blob of `pt`; false when it is not drawn (not in the cluster cut, or
// outside the depth range).
bool MakeBlob(Point pt, out Blob blob) {
  blob.center = vec2(0.0);
  blob.conic = vec3(1.0, 0.0, 1.0);
  blob.major = 1.0;
  blob.value = vec4(0.0);
  if (!InCut(pt)) return false;

  // Relative to the node's corner until the end of the move.
  vec3 p = (pt.position + 0.5) * b_node.x;
  vec3 velocity = b_columns1.x >= 0 ? Ranged(pt.velocity, b_velocity) : vec3(0.0);

  vec3 origin = this_draw.origin.xyz;
  if (u_modes.y != 0) {
    // Both epochs of an interval follow the same curve from p_e to p_e+1, so
    // the two copies of a particle coincide at every t.
    float t = u_time.x;
    float t2 = t * t, t3 = t2 * t;
    float h01 = u_modes.y == 2 ? 3.0 * t2 - 2.0 * t3 : t;
    float h10 = t3 - 2.0 * t2 + t, h11 = t3 - t2;
    if (u_modes.w > 0) {
      p += h01 * Ranged(pt.displacement, b_displacement);
      if (u_modes.y == 2) p += u_time.z * (h10 * velocity + h11 * Ranged(pt.next_velocity, b_next_velocity));
    } else {
      p += (1.0 - h01) * Ranged(pt.prev_displacement, b_prev_displacement);
      if (u_modes.y == 2) p += u_time.z * (h10 * Ranged(pt.prev_velocity, b_prev_velocity) + h11 * velocity);
    }
    if (u_wrap.x != 0) {
      // A path strays less than a box length from its ends, so one image is enough.
      origin = mix(origin, this_draw.origin_below.xyz, greaterThanEqual(p, this_draw.box_high.xyz));
      origin = mix(origin, this_draw.origin_above.xyz, lessThan(p, this_draw.box_low.xyz));
    }
  }
  p += origin;

  float depth = dot(p, u_forward.xyz);
  if (!(depth >= u_limits.x && depth <= u_limits.y)) return false;
  vec2 image = u_viewport.xy;
  float margin = u_viewport.z, focal = u_viewport.w;
  vec2 center = 0.5 * image + focal * vec2(dot(p, u_right.xyz), dot(p, u_up.xyz)) / depth;
  float smoothing = exp2(b_node.z + pt.smoothing * b_node.w);
  vec3 conic;
  float major, minor;
  Footprint(pt, smoothing * focal / depth, conic, major, minor);
  float weight = float(pt.weight) * b_node.y * u_limits.w * u_time.y;
  // Summed over the pixels where the integral would miss by more than a
  // fraction of a percent: small blobs, and thin ones.
  float normalization = major < kExactNormalizationRadius || minor < kExactNormalizationMinor
                            ? PixelSum(center, conic, major)
                            : kKernelIntegral * major * minor;

  // Where a point stands for many particles, their velocity dispersion
  // sigma (per axis) adds to the spread of speeds and of line-of-sight
  // velocities: speed is taken as the rms speed, and the line of sight's
  // second moment gains sigma^2.
  float sigma = b_columns2.z >= 0 ? b_dispersion.x + pt.velocity_dispersion * b_dispersion.y : 0.0;
  float shade = 0.0, spread = 0.0;
  int mode = u_modes.x;
  if (mode == 1) shade = sqrt(dot(velocity, velocity) + 3.0 * sigma * sigma);
  else if (mode == 2 || mode == 3) {
    shade = dot(velocity, u_forward.xyz);
    spread = sigma * sigma;
  } else if (mode == 4) shade = float(pt.type);
  float selected = 0.0;
  if (u_modes.z == 1 && b_columns1.y >= 0) selected = IsSelected(ParticleId(pt)) ? 1.0 : 0.0;

  blob.center = center + margin;
  // Counted as drawn where the raster path draws it: its centre in the
  // framebuffer (the image and its guard margin).
  if (u_cut.z != 0.0 && u_modes.z != 2 && all(greaterThanEqual(blob.center, vec2(0.0))) &&
      all(lessThan(blob.center, image + 2.0 * margin))) {
    atomicCounterIncrement(cut_points);
  }
  blob.conic = conic;
  blob.major = major;
  blob.value = u_modes.z == 2 ? vec4(0.0, 0.0, 0.0, weight / normalization)
                              : (weight / normalization) * vec4(1.0, shade, shade * shade + spread, selected);
  return true;
}
