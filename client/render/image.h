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

// Writes a PNG atomically (temporary file, then rename). Throws InputError
// naming the path when it cannot be written.
void writePng(const ImageRgb8& image, const std::filesystem::path& path);
// Reads a PNG (any channel count, converted to RGB). Throws InputError.
ImageRgb8 readPng(const std::filesystem::path& path);

}  // namespace vistream
