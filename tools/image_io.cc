#include "tools/image_io.h"

#include <png.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "base/error.h"
#include "tools/output_file.h"

namespace octocosm {
namespace {

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

// Writes through `write(file)` into a temporary file beside `path`, then
// renames it over `path` (tools/output_file.h).
template <typename Write>
void WriteAtomically(const std::string& path, Write write) {
  OutputFile output(path);
  File file(std::fopen(output.write_path().c_str(), "wb"));
  if (!file) throw IoErrorFromErrno(path, "creating the image", errno);
  bool ok = write(file.get());
  ok = ok && std::fflush(file.get()) == 0;
  const int error = errno;
  ok = std::fclose(file.release()) == 0 && ok;
  if (!ok) throw IoErrorFromErrno(path, "writing the image", error != 0 ? error : errno);
  output.Commit();
}

}  // namespace

void WritePng(const std::string& path, const RgbImage& image) {
  WriteAtomically(path, [&](std::FILE* file) {
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!png || !info) {
      png_destroy_write_struct(&png, &info);
      throw Error::Io(path, "libpng could not start a PNG");
    }
    // libpng reports errors by longjmp: nothing with a destructor may live
    // between here and the end of this block.
    std::vector<png_bytep> rows(static_cast<std::size_t>(image.height));
    for (int j = 0; j < image.height; ++j) {
      // PNG rows run top to bottom, the image's bottom to top.
      rows[static_cast<std::size_t>(j)] = const_cast<png_bytep>(
          image.rgb.data() + 3 * static_cast<std::size_t>(image.height - 1 - j) * static_cast<std::size_t>(image.width));
    }
    if (setjmp(png_jmpbuf(png))) {
      png_destroy_write_struct(&png, &info);
      return false;
    }
    png_init_io(png, file);
    png_set_IHDR(png, info, static_cast<png_uint_32>(image.width), static_cast<png_uint_32>(image.height), 8,
                 PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_write_info(png, info);
    png_write_image(png, rows.data());
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    return true;
  });
}

void WritePfm(const std::string& path, const HdrImage& image) {
  WriteAtomically(path, [&](std::FILE* file) {
    // A negative scale means little endian.
    if (std::fprintf(file, "Pf\n%d %d\n-1.0\n", image.width, image.height) < 0) return false;
    std::vector<float> row(static_cast<std::size_t>(image.width));
    for (int j = 0; j < image.height; ++j) {
      for (int i = 0; i < image.width; ++i) row[static_cast<std::size_t>(i)] = static_cast<float>(image.at(i, j, 0));
      if (std::fwrite(row.data(), sizeof(float), row.size(), file) != row.size()) return false;
    }
    return true;
  });
}

HdrImage ReadPfm(const std::string& path) {
  File file(std::fopen(path.c_str(), "rb"));
  if (!file) throw Error::NotFound(path + ": cannot open the image");
  char magic[3] = {};
  int width = 0, height = 0;
  double scale = 0;
  if (std::fscanf(file.get(), "%2s %d %d %lf", magic, &width, &height, &scale) != 4 || std::string(magic) != "Pf" ||
      std::fgetc(file.get()) != '\n') {
    throw Error::BadInput(path, "not a greyscale PFM file (expected 'Pf', width, height, scale)");
  }
  if (width < 1 || height < 1 || width > 65536 || height > 65536 || !(scale < 0)) {
    throw Error::BadInput(path, "a PFM of " + std::to_string(width) + "x" + std::to_string(height) + ", scale " +
                                    std::to_string(scale) + ": only little-endian images up to 65536 pixels a side are read");
  }
  HdrImage image{width, height, std::vector<double>(4 * static_cast<std::size_t>(width) * height, 0.0)};
  std::vector<float> row(static_cast<std::size_t>(width));
  for (int j = 0; j < height; ++j) {
    if (std::fread(row.data(), sizeof(float), row.size(), file.get()) != row.size()) {
      throw Error::BadInput(path, "truncated: row " + std::to_string(j) + " of " + std::to_string(height) + " is missing");
    }
    for (int i = 0; i < width; ++i) image.rgba[4 * (static_cast<std::size_t>(j) * width + i)] = row[static_cast<std::size_t>(i)];
  }
  return image;
}

RgbImage ReadPng(const std::string& path) {
  File file(std::fopen(path.c_str(), "rb"));
  if (!file) throw Error::NotFound(path + ": cannot open the image");
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw Error::BadInput(path, "libpng could not start reading");
  }
  RgbImage image;
  std::vector<std::uint8_t> pixels;
  std::vector<png_bytep> rows;
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw Error::BadInput(path, "not a readable PNG file");
  }
  png_init_io(png, file.get());
  png_read_info(png, info);
  png_set_strip_16(png);
  png_set_palette_to_rgb(png);
  png_set_gray_to_rgb(png);
  png_set_strip_alpha(png);
  png_read_update_info(png, info);
  image.width = static_cast<int>(png_get_image_width(png, info));
  image.height = static_cast<int>(png_get_image_height(png, info));
  pixels.resize(3 * static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height));
  rows.resize(static_cast<std::size_t>(image.height));
  for (int j = 0; j < image.height; ++j) {
    rows[static_cast<std::size_t>(j)] =
        pixels.data() + 3 * static_cast<std::size_t>(image.height - 1 - j) * static_cast<std::size_t>(image.width);
  }
  png_read_image(png, rows.data());
  png_destroy_read_struct(&png, &info, nullptr);
  image.rgb = std::move(pixels);
  return image;
}

}  // namespace octocosm
