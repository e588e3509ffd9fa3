// The compute path (render/compute_splatter.h): one invocation per point,
// read from its block's columns as storage buffers, turned into its blob by
// splat_point.glsl, and added pixel by pixel into a float buffer with atomic
// adds (GL_NV_shader_atomic_float, splat_accumulate.glsl) where the blob is
// small. A blob larger than u_compute_radius goes to a list that a workgroup
// a blob adds after this dispatch (splat_large_comp.glsl); if the list is
// full the thread adds it itself, so no blob is lost.
//
// Before this file the program defines which columns it reads (the frame's
// colour mode, interpolation and selection decide): HAS_VELOCITY,
// HAS_DISPERSION, HAS_TYPE, HAS_ID, HAS_LINKS (displacements), HAS_HERMITE
// (the neighbours' velocities), HAS_CUT (the cluster cut's entries). The
// others are not bound and read as zero.

layout(local_size_x = 256) in;

// The dispatch: draws [u_first_draw, u_first_draw + u_draw_count) of Draws,
// all of one pool, u_points points in all; the columns are bound from pool
// point u_base on. Ids are u32 offsets (1 word) or whole u64 IDs (2 words).
uniform uint u_first_draw;
uniform uint u_draw_count;
uniform uint u_points;
uniform uint u_base;
uniform uint u_id_words;
uniform float u_compute_radius;  // pixels: larger blobs go to the list

// Columns as words; element i of a column of s-byte elements starts at byte s i.
layout(std430, binding = 5) readonly buffer PositionColumn { uint position_words[]; };
layout(std430, binding = 6) readonly buffer WeightColumn { uint weight_words[]; };
layout(std430, binding = 7) readonly buffer SmoothingColumn { uint smoothing_words[]; };
layout(std430, binding = 8) readonly buffer ShapeColumn { uint shape_words[]; };
#ifdef HAS_VELOCITY
layout(std430, binding = 9) readonly buffer VelocityColumn { uint velocity_words[]; };
#endif
#ifdef HAS_DISPERSION
layout(std430, binding = 10) readonly buffer DispersionColumn { uint dispersion_words[]; };
#endif
#ifdef HAS_TYPE
layout(std430, binding = 11) readonly buffer TypeColumn { uint type_words[]; };
#endif
#ifdef HAS_ID
layout(std430, binding = 12) readonly buffer IdColumn { uint id_words[]; };
#endif
#ifdef HAS_LINKS
layout(std430, binding = 13) readonly buffer DisplacementColumn { uint displacement_words[]; };
layout(std430, binding = 14) readonly buffer PrevDisplacementColumn { uint prev_displacement_words[]; };
#endif
#ifdef HAS_CUT
layout(std430, binding = 19) readonly buffer CutColumn { uint cut_words[]; };
#endif
#ifdef HAS_HERMITE
layout(std430, binding = 15) readonly buffer NextVelocityColumn { uint next_velocity_words[]; };
layout(std430, binding = 16) readonly buffer PrevVelocityColumn { uint prev_velocity_words[]; };
#endif

#define U16(words, index) ((words[(index) >> 1u] >> (((index) & 1u) << 4u)) & 0xFFFFu)
#define U8(words, index) ((words[(index) >> 2u] >> (((index) & 3u) << 3u)) & 0xFFu)
#define U16X3(words, i) vec3(float(U16(words, 3u * (i))), float(U16(words, 3u * (i) + 1u)), float(U16(words, 3u * (i) + 2u)))

// The draw that point `k` of the dispatch belongs to: the last whose first
// point (block.w) is at most k.
uint DrawOf(uint k) {
  uint low = 0u, high = u_draw_count - 1u;
  while (low < high) {
    uint middle = (low + high + 1u) >> 1u;
    if (draws[u_first_draw + middle].block.w <= k) low = middle;
    else high = middle - 1u;
  }
  return u_first_draw + low;
}

Point Load(uint draw, uint i) {
  Point pt;
  pt.draw = draw;
  pt.position = U16X3(position_words, i);
  pt.weight = weight_words[i];
  pt.smoothing = float(U16(smoothing_words, i));
  pt.type = 0u;
  pt.velocity = vec3(0.0);
  pt.id = uvec2(0u);
  pt.displacement = vec3(0.0);
  pt.next_velocity = vec3(0.0);
  pt.prev_displacement = vec3(0.0);
  pt.prev_velocity = vec3(0.0);
  pt.velocity_dispersion = 0.0;
  pt.shape_diagonal = vec3(0.0);
  pt.shape_off_diagonal = vec3(0.0);
  if (b_columns2.w >= 0) {
    pt.shape_diagonal = vec3(float(U8(shape_words, 6u * i)), float(U8(shape_words, 6u * i + 1u)),
                             float(U8(shape_words, 6u * i + 2u)));
    pt.shape_off_diagonal = vec3(float(U8(shape_words, 6u * i + 3u)), float(U8(shape_words, 6u * i + 4u)),
                                 float(U8(shape_words, 6u * i + 5u)));
  }
  pt.own_bound = vec3(0.0);
  pt.parent = uvec3(0u);
#ifdef HAS_CUT
  // Only draws that take part in the cut have the column (in pools without
  // it a placeholder is bound). A 20-byte entry (render/cluster_links.h, ClusterCutEntry): 3 x u16, a spare u16, 3 x u32.
  if ((draws[draw].cut.x & kCutApplies) != 0u) {
    pt.own_bound = vec3(float(U16(cut_words, 10u * i)), float(U16(cut_words, 10u * i + 1u)), float(U16(cut_words, 10u * i + 2u)));
    pt.parent = uvec3(cut_words[5u * i + 2u], cut_words[5u * i + 3u], cut_words[5u * i + 4u]);
  }
#endif
#ifdef HAS_VELOCITY
  if (b_columns1.x >= 0) pt.velocity = U16X3(velocity_words, i);
#endif
#ifdef HAS_DISPERSION
  if (b_columns2.z >= 0) pt.velocity_dispersion = float(U16(dispersion_words, i));
#endif
#ifdef HAS_TYPE
  if (b_columns0.w >= 0) pt.type = U8(type_words, i);
#endif
#ifdef HAS_ID
  if (b_columns1.y >= 0) pt.id = u_id_words == 2u ? uvec2(id_words[2u * i], id_words[2u * i + 1u]) : uvec2(id_words[i], 0u);
#endif
#ifdef HAS_LINKS
  if (b_columns1.z >= 0) pt.displacement = U16X3(displacement_words, i);
  if (b_columns2.x >= 0) pt.prev_displacement = U16X3(prev_displacement_words, i);
#endif
#ifdef HAS_HERMITE
  if (b_columns1.w >= 0) pt.next_velocity = U16X3(next_velocity_words, i);
  if (b_columns2.y >= 0) pt.prev_velocity = U16X3(prev_velocity_words, i);
#endif
  return pt;
}

// Adds the blob to every pixel whose centre its footprint covers: the pixels
// splat_frag.glsl would shade, with the same weights.
void AddPixels(Blob blob) {
  ivec2 low, high;
  PixelBox(blob.center, blob.major, low, high);
  for (int j = low.y; j <= high.y; ++j) {
    for (int i = low.x; i <= high.x; ++i) AddPixel(ivec2(i, j), blob.center, blob.conic, blob.value);
  }
}

void main() {
  uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
  for (uint k = gl_GlobalInvocationID.x; k < u_points; k += stride) {
    uint draw = DrawOf(k);
    uint i = draws[draw].block.y + (k - draws[draw].block.w) - u_base;
    Blob blob;
    if (!MakeBlob(Load(draw, i), blob)) continue;
    // The raster path draws a point only if its centre is in the
    // framebuffer; so does this one.
    if (!(all(greaterThanEqual(blob.center, vec2(0.0))) && all(lessThan(blob.center, vec2(u_target_size))))) continue;
    if (blob.major > u_compute_radius) {
      uint slot = atomicAdd(large_count, 1u);
      if (slot < uint(large_blobs.length())) {
        large_blobs[slot].center_major = vec4(blob.center, blob.major, 0.0);
        large_blobs[slot].conic = vec4(blob.conic, 0.0);
        large_blobs[slot].value = blob.value;
        continue;
      }
    }
    AddPixels(blob);
  }
}
