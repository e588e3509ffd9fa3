// The accumulation buffer -> colours: render/tone_map.h, the same arithmetic.

layout(binding = 0) uniform sampler2D u_hdr;
uniform ivec2 u_offset;       // accumulation texel of this pixel = gl_FragCoord.xy - u_viewport_origin + u_offset
uniform ivec2 u_viewport_origin;
uniform float u_mass_unit;    // the accumulation holds mass / u_mass_unit
uniform int u_curve;          // 0 log, 1 asinh
uniform float u_exposure;
uniform float u_floor;
uniform int u_color_mode;     // ColorMode
uniform float u_attribute_low;
uniform float u_attribute_high;
uniform vec3 u_density_map[33];
uniform vec3 u_attribute_map[33];
uniform vec3 u_highlight;

layout(location = 0) out vec4 out_color;

vec3 DensityMap(float t) {
  float x = clamp(isnan(t) ? 0.0 : t, 0.0, 1.0) * 32.0;
  int i = min(int(x), 31);
  return mix(u_density_map[i], u_density_map[i + 1], x - float(i));
}

vec3 AttributeMap(float t) {
  float x = clamp(isnan(t) ? 0.0 : t, 0.0, 1.0) * 32.0;
  int i = min(int(x), 31);
  return mix(u_attribute_map[i], u_attribute_map[i + 1], x - float(i));
}

float Brightness(float d) {
  if (!(d > 0.0)) return 0.0;
  float b = u_curve == 0 ? log(d / u_floor) / log(u_exposure / u_floor)
                         : asinh(d / u_floor) / asinh(u_exposure / u_floor);
  return clamp(b, 0.0, 1.0);
}

void main() {
  vec4 v = texelFetch(u_hdr, ivec2(gl_FragCoord.xy) - u_viewport_origin + u_offset, 0);
  float d = v.x * u_mass_unit;
  float b = Brightness(d);
  vec3 rgb;
  if (u_color_mode == 0) {
    rgb = DensityMap(b);
  } else {
    float x = 0.0;
    if (v.x > 0.0) {
      float mean = v.y / v.x;
      x = u_color_mode == 3 ? sqrt(max(v.z / v.x - mean * mean, 0.0)) : mean;
    }
    rgb = AttributeMap((x - u_attribute_low) / (u_attribute_high - u_attribute_low)) * b;
  }
  float h = Brightness(v.w * u_mass_unit);
  out_color = vec4(rgb * (1.0 - h) + u_highlight * h, 1.0);
}
