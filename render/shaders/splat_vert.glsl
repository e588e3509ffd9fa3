// The raster path: one vertex per point, fetched as vertex attributes from
// the block's columns (render/gpu_block_arena.h), drawn as a point sprite
// that splat_frag.glsl fills with the blob of splat_point.glsl.

layout(location = 0) in vec3 a_position;
layout(location = 1) in uint a_weight;
layout(location = 2) in float a_smoothing;
layout(location = 3) in uint a_type;
layout(location = 4) in vec3 a_velocity;
layout(location = 5) in uvec2 a_id;
layout(location = 6) in vec3 a_displacement;
layout(location = 7) in vec3 a_next_velocity;
layout(location = 8) in vec3 a_prev_displacement;
layout(location = 9) in vec3 a_prev_velocity;
layout(location = 10) in float a_velocity_dispersion;
layout(location = 11) in vec3 a_shape_diagonal;
layout(location = 12) in vec3 a_shape_off_diagonal;
layout(location = 13) in uint a_draw;  // the draw's index in Draws: its base instance
layout(location = 14) in vec3 a_own_bound;
layout(location = 15) in uvec3 a_parent;

flat out vec2 v_center;  // framebuffer coordinates
flat out vec3 v_conic;
flat out vec4 v_value;

void main() {
  Point pt;
  pt.position = a_position;
  pt.weight = a_weight;
  pt.smoothing = a_smoothing;
  pt.type = a_type;
  pt.velocity = a_velocity;
  pt.id = a_id;
  pt.displacement = a_displacement;
  pt.next_velocity = a_next_velocity;
  pt.prev_displacement = a_prev_displacement;
  pt.prev_velocity = a_prev_velocity;
  pt.velocity_dispersion = a_velocity_dispersion;
  pt.shape_diagonal = a_shape_diagonal;
  pt.shape_off_diagonal = a_shape_off_diagonal;
  pt.own_bound = a_own_bound;
  pt.parent = a_parent;
  pt.draw = a_draw;
  Blob blob;
  if (!MakeBlob(pt, blob)) {
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);  // outside the clip volume: no fragments
    gl_PointSize = 1.0;
    v_center = vec2(0.0);
    v_conic = vec3(1.0, 0.0, 1.0);
    v_value = vec4(0.0);
    return;
  }
  vec2 framebuffer = u_viewport.xy + 2.0 * u_viewport.z;
  v_center = blob.center;
  v_conic = blob.conic;
  v_value = blob.value;
  gl_Position = vec4(blob.center / framebuffer * 2.0 - 1.0, 0.0, 1.0);
  gl_PointSize = 2.0 * blob.major + kSpriteGuard;
}
