// Shared by the splat shaders: the kernel of render/splat_kernel.h.
// (Each program is built from "#version 450 core", this file and its stage.)

const float kKernelIntegral = 0.54977871437821381673;  // 7 pi / 40
const float kExactNormalizationRadius = 4.0;
const float kExactNormalizationMinor = 2.0;  // pixels: below, an ellipse's pixel sum strays from its integral
const float kSpriteGuard = 1.0 / 16.0;  // pixels: see SpriteSize

// W(q): the two-dimensional cubic spline (M4).
float CubicKernel(float q) {
  if (!(q < 1.0)) return 0.0;
  if (q < 0.5) return 1.0 - 6.0 * q * q + 6.0 * q * q * q;
  float r = 1.0 - q;
  return 2.0 * r * r * r;
}

// q for a pixel offset d from a blob's centre.
float FootprintDistance(vec3 conic, vec2 d) {
  return sqrt(conic.x * d.x * d.x + 2.0 * conic.y * d.x * d.y + conic.z * d.y * d.y);
}
