#include "client/render/image.h"

#include <stb_image.h>
#include <stb_image_write.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "common/core/atomic_file.h"
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
  std::vector<uint8_t> png;
  auto append = [](void* context, void* data, int size) {
    auto* out = static_cast<std::vector<uint8_t>*>(context);
    const auto* bytes = static_cast<const uint8_t*>(data);
    out->insert(out->end(), bytes, bytes + size);
  };
  if (!stbi_write_png_to_func(append, &png, image.width, image.height, 3, image.pixels.data(),
                              image.width * 3))
    throwInputError("{}: cannot encode PNG", path.string());
  writeFileAtomically(path, png);
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

ImageContrast imageContrast(const ImageRgb8& image) {
  ImageContrast c;
  const size_t n = size_t(image.width) * size_t(image.height);
  if (n == 0) return c;
  std::vector<uint64_t> seen(size_t(1) << 18, 0);  // a bit per 24-bit colour
  double sum = 0.0, sum2 = 0.0;
  for (size_t p = 0; p < n; ++p) {
    const uint8_t* px = image.pixels.data() + 3 * p;
    const uint32_t colour = uint32_t(px[0]) << 16 | uint32_t(px[1]) << 8 | px[2];
    uint64_t& word = seen[colour >> 6];
    const uint64_t bit = uint64_t(1) << (colour & 63);
    c.distinctColours += (word & bit) == 0;
    word |= bit;
    const double y = 0.2126 * px[0] + 0.7152 * px[1] + 0.0722 * px[2];
    sum += y;
    sum2 += y * y;
  }
  const double mean = sum / double(n);
  c.luminanceStd = std::sqrt(std::max(0.0, sum2 / double(n) - mean * mean));
  return c;
}

ImageRgb8 contactSheet(const std::vector<ImageRgb8>& tiles, int columns, int gap,
                       glm::u8vec3 background) {
  if (tiles.empty() || columns < 1) return {};
  const int w = tiles[0].width, h = tiles[0].height;
  const int cols = std::min<int>(columns, int(tiles.size()));
  const int rows = int((tiles.size() + size_t(cols) - 1) / size_t(cols));
  ImageRgb8 sheet(gap + cols * (w + gap), gap + rows * (h + gap), background);
  for (size_t k = 0; k < tiles.size(); ++k) {
    VS_CHECK(tiles[k].width == w && tiles[k].height == h);
    const int x0 = gap + int(k % size_t(cols)) * (w + gap),
              y0 = gap + int(k / size_t(cols)) * (h + gap);
    for (int y = 0; y < h; ++y)
      std::memcpy(sheet.pixels.data() + 3 * (size_t(y0 + y) * size_t(sheet.width) + size_t(x0)),
                  tiles[k].pixels.data() + 3 * size_t(y) * size_t(w), 3 * size_t(w));
  }
  return sheet;
}

ImageRgb8 stackImages(const ImageRgb8& top, const ImageRgb8& bottom, glm::u8vec3 background) {
  ImageRgb8 out(std::max(top.width, bottom.width), top.height + bottom.height, background);
  auto paste = [&](const ImageRgb8& im, int y0) {
    for (int y = 0; y < im.height; ++y)
      std::memcpy(out.pixels.data() + 3 * size_t(y0 + y) * size_t(out.width),
                  im.pixels.data() + 3 * size_t(y) * size_t(im.width), 3 * size_t(im.width));
  };
  paste(top, 0);
  paste(bottom, top.height);
  return out;
}

}  // namespace vistream
