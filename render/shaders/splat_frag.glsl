// Adds the blob's share to each pixel it covers (additive blending into the
// RGBA32F accumulation buffer).

flat in vec2 v_center;
flat in vec3 v_conic;
flat in vec4 v_value;

layout(location = 0) out vec4 out_value;

void main() {
  float q = FootprintDistance(v_conic, gl_FragCoord.xy - v_center);
  if (q >= 1.0) discard;
  out_value = v_value * CubicKernel(q);
}
