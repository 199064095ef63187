// An 8-bit RGB image and PNG output, for headless frames and plots.
#pragma once

#include <cstdint>
#include <filesystem>
#include <glm/glm.hpp>
#include <vector>

namespace vistream {

struct ImageRgb8 {
  int width = 0, height = 0;
  std::vector<uint8_t> pixels;  // row-major, top row first, 3 bytes per pixel

  ImageRgb8() = default;
  ImageRgb8(int w, int h, glm::u8vec3 fill = {0, 0, 0});
  glm::u8vec3 at(int x, int y) const;
  void set(int x, int y, glm::u8vec3 c);
};

// How much a frame shows: its distinct colours and the standard deviation of
// its luminance (Rec. 709 weights on the 8-bit values), over every pixel.
struct ImageContrast {
  size_t distinctColours = 0;
  double luminanceStd = 0.0;
};
ImageContrast imageContrast(const ImageRgb8& image);

// Tiles of one size side by side in `columns` columns (rows as needed),
// `gap` pixels of `background` between and around them. Empty without tiles;
// tiles of another size than the first are a broken invariant (VS_CHECK).
ImageRgb8 contactSheet(const std::vector<ImageRgb8>& tiles, int columns, int gap = 4,
                       glm::u8vec3 background = {24, 24, 24});
// `bottom` below `top` (the wider's width; the narrower padded with `background`).
ImageRgb8 stackImages(const ImageRgb8& top, const ImageRgb8& bottom,
                      glm::u8vec3 background = {24, 24, 24});

// Writes a PNG atomically (temporary file, then rename). Throws InputError
// naming the path when it cannot be written.
void writePng(const ImageRgb8& image, const std::filesystem::path& path);
// Reads a PNG (any channel count, converted to RGB). Throws InputError.
ImageRgb8 readPng(const std::filesystem::path& path);

}  // namespace vistream
