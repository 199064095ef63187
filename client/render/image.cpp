#include "client/render/image.h"

#include <stb_image.h>
#include <stb_image_write.h>

#include "common/core/check.h"
#include "common/core/error.h"

namespace vistream {

ImageRgb8::ImageRgb8(int w, int h, glm::u8vec3 fill) : width(w), height(h) {
  VS_CHECK(w >= 0 && h >= 0);
  pixels.resize(size_t(w) * size_t(h) * 3);
  for (size_t i = 0; i < pixels.size(); i += 3) {
    pixels[i] = fill.r;
    pixels[i + 1] = fill.g;
    pixels[i + 2] = fill.b;
  }
}

glm::u8vec3 ImageRgb8::at(int x, int y) const {
  VS_DCHECK(x >= 0 && y >= 0 && x < width && y < height);
  const size_t i = (size_t(y) * size_t(width) + size_t(x)) * 3;
  return {pixels[i], pixels[i + 1], pixels[i + 2]};
}

void ImageRgb8::set(int x, int y, glm::u8vec3 c) {
  VS_DCHECK(x >= 0 && y >= 0 && x < width && y < height);
  const size_t i = (size_t(y) * size_t(width) + size_t(x)) * 3;
  pixels[i] = c.r;
  pixels[i + 1] = c.g;
  pixels[i + 2] = c.b;
}

void writePng(const ImageRgb8& image, const std::filesystem::path& path) {
  if (image.width <= 0 || image.height <= 0)
    throwInputError("{}: cannot write an empty image", path.string());
  const std::filesystem::path tmp = path.string() + ".tmp";
  if (!stbi_write_png(tmp.string().c_str(), image.width, image.height, 3, image.pixels.data(),
                      image.width * 3))
    throwInputError("{}: cannot write PNG", tmp.string());
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throwInputError("{}: cannot rename into place: {}", path.string(), ec.message());
}

ImageRgb8 readPng(const std::filesystem::path& path) {
  int w = 0, h = 0, n = 0;
  unsigned char* data = stbi_load(path.string().c_str(), &w, &h, &n, 3);
  if (!data)
    throwInputError(InputErrorCode::BadFile, "{}: cannot read image: {}", path.string(),
                    stbi_failure_reason());
  ImageRgb8 img;
  img.width = w;
  img.height = h;
  img.pixels.assign(data, data + size_t(w) * size_t(h) * 3);
  stbi_image_free(data);
  return img;
}

}  // namespace vistream
