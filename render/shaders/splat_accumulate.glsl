// Shared by the compute path's programs (render/compute_splatter.h): the
// accumulation they add blobs into with atomics, the list of large blobs, and
// the addition of one blob to one pixel, as splat_frag.glsl shades it.
// (The program's first source enables GL_NV_shader_atomic_float: an
// #extension must precede the code of the files before this one.)

// Four floats per pixel, rows from the bottom, as the accumulation texture
// (render/splat_renderer.h).
layout(std430, binding = 17) buffer Accumulation { float accumulation[]; };

struct LargeBlob {
  vec4 center_major;  // centre (x, y), larger radius, unused
  vec4 conic;         // xyz
  vec4 value;
};
// The blobs larger than the compute radius, each added by a whole workgroup
// (splat_large_comp.glsl). The count may exceed the capacity: the blobs past
// it were added by their own thread.
layout(std430, binding = 18) buffer LargeBlobs {
  uint large_count;
  uint large_pad0;
  uint large_pad1;
  uint large_pad2;
  LargeBlob large_blobs[];
};

uniform ivec2 u_target_size;  // the accumulation buffer, guard margin included

void AddChannel(uint at, float value) {
  if (value != 0.0) atomicAdd(accumulation[at], value);
}

// Adds the blob centred at `center` to `pixel` (inside the target).
void AddPixel(ivec2 pixel, vec2 center, vec3 conic, vec4 value) {
  float w = CubicKernel(FootprintDistance(conic, vec2(pixel) + 0.5 - center));
  if (w <= 0.0) return;
  uint at = 4u * (uint(pixel.y) * uint(u_target_size.x) + uint(pixel.x));
  vec4 v = value * w;
  AddChannel(at, v.x);
  AddChannel(at + 1u, v.y);
  AddChannel(at + 2u, v.z);
  AddChannel(at + 3u, v.w);
}

// The pixels whose centres a blob's footprint may cover, within the target:
// [low, high] (empty where high < low).
void PixelBox(vec2 center, float major, out ivec2 low, out ivec2 high) {
  low = max(ivec2(ceil(center - major - 0.5)), ivec2(0));
  high = min(ivec2(floor(center + major - 0.5)), u_target_size - 1);
}
