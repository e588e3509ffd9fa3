// Images the renderer hands back, in memory (render/ writes no files; the
// tools write PNG and PFM). Rows run bottom to top, as OpenGL stores them:
// pixel (i, j) is element j * width + i, j = 0 the bottom row.
#pragma once

#include <cstdint>
#include <vector>

namespace octocosm {

// The accumulation buffer: four channels per pixel, summed over every blob
// that covers the pixel, each blob's share w * W / N (render/splat_kernel.h)
// times:
//   [0] 1                       mass per pixel ("density")
//   [1] a                       a = the point's colour attribute (render/tone_map.h)
//   [2] a * a
//   [3] 1 if the point's ID is selected, else 0
struct HdrImage {
  int width = 0;
  int height = 0;
  std::vector<double> rgba;  // 4 * width * height

  double at(int i, int j, int channel) const { return rgba[4 * (static_cast<std::size_t>(j) * width + i) + channel]; }
};

// A tone-mapped picture: sRGB values in [0, 1].
struct DisplayImage {
  int width = 0;
  int height = 0;
  std::vector<float> rgb;  // 3 * width * height
};

// 8-bit sRGB, what PNG files hold.
struct RgbImage {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgb;  // 3 * width * height
};

}  // namespace octocosm
