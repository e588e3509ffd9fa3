// Adds the compute path's accumulation (four floats per pixel) into the
// accumulation texture, where the raster path and everything after the
// splatting read, and clears it for the next dispatch.

layout(local_size_x = 16, local_size_y = 16) in;

layout(rgba32f, binding = 0) uniform image2D u_target;
uniform ivec2 u_size;

layout(std430, binding = 17) buffer Accumulation { vec4 accumulation[]; };

void main() {
  ivec2 p = ivec2(gl_GlobalInvocationID.xy);
  if (any(greaterThanEqual(p, u_size))) return;
  uint at = uint(p.y) * uint(u_size.x) + uint(p.x);
  vec4 v = accumulation[at];
  if (v == vec4(0.0)) return;
  imageStore(u_target, p, imageLoad(u_target, p) + v);
  accumulation[at] = vec4(0.0);
}
