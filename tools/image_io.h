// Writing pictures: PNG (8-bit sRGB, through libpng) and PFM (the mass per
// pixel as 32-bit floats, for analysis). Files are written under a temporary
// name and renamed (tools/output_file.h), so a failed or interrupted write
// leaves nothing behind.
#pragma once

#include <string>

#include "render/image.h"

namespace octocosm {

// Throws Error::Io naming the file when it cannot be written.
void WritePng(const std::string& path, const RgbImage& image);
// Greyscale PFM ("Pf", little endian, rows bottom to top as PFM has them) of
// channel 0 of the accumulation: mass per pixel.
void WritePfm(const std::string& path, const HdrImage& image);
// Reads a greyscale little-endian PFM (as WritePfm writes) into channel 0 of
// an accumulation image (the other channels 0). Throws Error::NotFound /
// Error::BadInput naming the file.
HdrImage ReadPfm(const std::string& path);
// Reads a PNG written by WritePng (8-bit RGB or RGBA), for tests and tools.
// Throws Error::NotFound / Error::BadInput naming the file.
RgbImage ReadPng(const std::string& path);

}  // namespace octocosm
