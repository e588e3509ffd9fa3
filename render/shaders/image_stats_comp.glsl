// The two passes of ImageStatistics (render/tone_map.h) over the image part
// of the accumulation buffer. Pass 0: the largest density and the attribute's
// range; pass 1: the histograms. Floats are compared as ordered integers so
// that atomicMin/atomicMax work on them. Each workgroup reduces its pixels in
// shared memory first and adds to the buffer once per value or bin: a
// million pixels' atomics on one word (or a few bins) would queue up behind
// each other on a GPU.

layout(local_size_x = 16, local_size_y = 16) in;

layout(binding = 0) uniform sampler2D u_hdr;
uniform ivec2 u_offset;   // texel of image pixel (0, 0)
uniform ivec2 u_size;     // image size
uniform int u_pass;
uniform int u_color_mode;
uniform float u_mass_unit;

layout(std430, binding = 2) buffer Statistics {
  uint s_max_density;   // float bits (densities are positive)
  uint s_attribute_min; // ordered float bits
  uint s_attribute_max;
  uint s_pad;
  uint s_density[1024];
  uint s_attribute[1024];
};

uint Ordered(float f) {
  uint u = floatBitsToUint(f);
  return (u & 0x80000000u) != 0u ? ~u : (u | 0x80000000u);
}

float Unordered(uint u) { return uintBitsToFloat((u & 0x80000000u) != 0u ? (u & 0x7FFFFFFFu) : ~u); }

int Bin(float fraction) { return int(clamp(floor(fraction * 1024.0), 0.0, 1023.0)); }

shared uint g_max_density;
shared uint g_attribute_min;
shared uint g_attribute_max;
shared uint g_density[1024];
shared uint g_attribute[1024];

void main() {
  uint lane = gl_LocalInvocationIndex;  // 0..255
  if (u_pass == 0) {
    if (lane == 0u) {
      g_max_density = 0u;
      g_attribute_min = 0xFFFFFFFFu;
      g_attribute_max = 0u;
    }
  } else {
    for (uint b = lane; b < 1024u; b += 256u) {
      g_density[b] = 0u;
      g_attribute[b] = 0u;
    }
  }
  barrier();

  ivec2 pixel = ivec2(gl_GlobalInvocationID.xy);
  bool inside = pixel.x < u_size.x && pixel.y < u_size.y;
  vec4 v = inside ? texelFetch(u_hdr, pixel + u_offset, 0) : vec4(0.0);
  float d = v.x * u_mass_unit;
  if (d > 0.0) {
    float x = 0.0;
    if (u_color_mode != 0) {
      float mean = v.y / v.x;
      x = u_color_mode == 3 ? sqrt(max(v.z / v.x - mean * mean, 0.0)) : mean;
    }
    if (u_pass == 0) {
      atomicMax(g_max_density, floatBitsToUint(d));
      if (u_color_mode != 0) {
        atomicMin(g_attribute_min, Ordered(x));
        atomicMax(g_attribute_max, Ordered(x));
      }
    } else {
      float max_density = uintBitsToFloat(s_max_density);
      atomicAdd(g_density[Bin((log2(d / max_density) + 32.0) / 32.0)], 1u);
      if (u_color_mode != 0 && d >= max_density / 1024.0) {
        float lo = Unordered(s_attribute_min), hi = Unordered(s_attribute_max);
        atomicAdd(g_attribute[hi > lo ? Bin((x - lo) / (hi - lo)) : 0], 1u);
      }
    }
  }
  barrier();

  if (u_pass == 0) {
    if (lane == 0u && g_max_density != 0u) {
      atomicMax(s_max_density, g_max_density);
      if (u_color_mode != 0) {
        atomicMin(s_attribute_min, g_attribute_min);
        atomicMax(s_attribute_max, g_attribute_max);
      }
    }
    return;
  }
  for (uint b = lane; b < 1024u; b += 256u) {
    if (g_density[b] != 0u) atomicAdd(s_density[b], g_density[b]);
    if (g_attribute[b] != 0u) atomicAdd(s_attribute[b], g_attribute[b]);
  }
}
