// The compute path's large blobs (splat_comp.glsl lists them), drawn as
// point sprites that splat_frag.glsl fills, as the raster path draws them.
// The list's count may exceed its capacity (the compute shader added those
// blobs itself): vertices past the capacity draw nothing.

struct LargeBlob {
  vec4 center_major;
  vec4 conic;
  vec4 value;
};
layout(std430, binding = 18) readonly buffer LargeBlobs {
  uint large_count;
  uint large_instances;
  uint large_first;
  uint large_base_instance;
  LargeBlob large_blobs[];
};

uniform vec2 u_framebuffer;  // pixels, guard margin included

flat out vec2 v_center;
flat out vec3 v_conic;
flat out vec4 v_value;

void main() {
  if (gl_VertexID >= large_blobs.length()) {
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);  // outside the clip volume: no fragments
    gl_PointSize = 1.0;
    v_center = vec2(0.0);
    v_conic = vec3(1.0, 0.0, 1.0);
    v_value = vec4(0.0);
    return;
  }
  LargeBlob blob = large_blobs[gl_VertexID];
  v_center = blob.center_major.xy;
  v_conic = blob.conic.xyz;
  v_value = blob.value;
  gl_Position = vec4(v_center / u_framebuffer * 2.0 - 1.0, 0.0, 1.0);
  gl_PointSize = 2.0 * blob.center_major.z + kSpriteGuard;
}
