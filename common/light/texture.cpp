#include "common/light/texture.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <stb_image.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "common/scene/scene.h"

namespace vistream {
namespace {

constexpr int kMaxTextureSide = 16384;

int64_t floorDiv(int64_t a, int64_t b) {
  return a >= 0 ? a / b : -((-a + b - 1) / b);
}

std::optional<Texture> fromStb(stbi_uc* pixels, int w, int h, std::string& error) {
  std::unique_ptr<stbi_uc, void (*)(void*)> owned(pixels, stbi_image_free);
  if (!pixels) {
    error = stbi_failure_reason() ? stbi_failure_reason() : "cannot decode the image";
    return std::nullopt;
  }
  if (w <= 0 || h <= 0 || w > kMaxTextureSide || h > kMaxTextureSide) {
    error = "the image is " + std::to_string(w) + "x" + std::to_string(h) + " pixels";
    return std::nullopt;
  }
  std::vector<glm::vec3> texels(size_t(w) * size_t(h));
  for (size_t i = 0; i < texels.size(); ++i)
    texels[i] = glm::vec3(srgbToLinear(pixels[3 * i]), srgbToLinear(pixels[3 * i + 1]),
                          srgbToLinear(pixels[3 * i + 2]));
  return Texture::fromLinear(w, h, std::move(texels));
}

}  // namespace

float srgbToLinear(uint8_t c) {
  const float s = float(c) / 255.0f;
  return s <= 0.04045f ? s / 12.92f : std::pow((s + 0.055f) / 1.055f, 2.4f);
}

std::optional<Texture> Texture::load(const std::filesystem::path& file, std::string& error) {
  int w = 0, h = 0, n = 0;
  if (!stbi_info(file.string().c_str(), &w, &h, &n)) {
    error = stbi_failure_reason() ? stbi_failure_reason() : "not an image";
    return std::nullopt;
  }
  if (w > kMaxTextureSide || h > kMaxTextureSide) {  // checked before decoding
    error = "the image is " + std::to_string(w) + "x" + std::to_string(h) + " pixels";
    return std::nullopt;
  }
  return fromStb(stbi_load(file.string().c_str(), &w, &h, &n, 3), w, h, error);
}

std::optional<Texture> Texture::decode(std::span<const uint8_t> bytes, std::string& error) {
  if (bytes.empty() || bytes.size() > size_t(std::numeric_limits<int>::max())) {
    error = "no image bytes";
    return std::nullopt;
  }
  int w = 0, h = 0, n = 0;
  if (!stbi_info_from_memory(bytes.data(), int(bytes.size()), &w, &h, &n)) {
    error = stbi_failure_reason() ? stbi_failure_reason() : "not an image";
    return std::nullopt;
  }
  if (w > kMaxTextureSide || h > kMaxTextureSide) {
    error = "the image is " + std::to_string(w) + "x" + std::to_string(h) + " pixels";
    return std::nullopt;
  }
  return fromStb(stbi_load_from_memory(bytes.data(), int(bytes.size()), &w, &h, &n, 3), w, h,
                 error);
}

Texture Texture::fromLinear(int width, int height, std::vector<glm::vec3> texels) {
  Texture t;
  t.width_ = width;
  t.height_ = height;
  const size_t stride = size_t(width) + 1;
  t.table_.assign(stride * (size_t(height) + 1), glm::dvec3(0.0));
  for (int y = 0; y < height; ++y) {
    glm::dvec3 row(0.0);
    for (int x = 0; x < width; ++x) {
      row += glm::dvec3(texels[size_t(y) * size_t(width) + size_t(x)]);
      t.table_[size_t(y + 1) * stride + size_t(x + 1)] =
          t.table_[size_t(y) * stride + size_t(x + 1)] + row;
    }
  }
  return t;
}

glm::dvec3 Texture::sat(int64_t x, int64_t y) const {
  return table_[size_t(y) * (size_t(width_) + 1) + size_t(x)];
}

glm::dvec3 Texture::boxSum(int64_t x0, int64_t x1, int64_t y0, int64_t y1) const {
  // Whole periods first, then the wrapped remainder of each axis.
  auto split = [](int64_t a0, int64_t a1, int64_t n) {
    struct Parts {
      int64_t whole;
      int64_t lo, hi;  // a remainder [lo, hi) within [0, 2n)
    };
    const int64_t shift = floorDiv(a0, n) * n;
    a0 -= shift;
    a1 -= shift;
    const int64_t whole = (a1 - a0) / n;
    return Parts{whole, a0, a1 - whole * n};
  };
  const auto px = split(x0, x1, width_);
  const auto py = split(y0, y1, height_);
  // Sum over [lo, hi) of one axis, hi up to 2n, as up to two ranges in [0, n).
  auto ranges = [](int64_t lo, int64_t hi, int64_t n, int64_t out[2][2]) {
    if (hi <= n) {
      out[0][0] = lo, out[0][1] = hi;
      return 1;
    }
    out[0][0] = lo, out[0][1] = n;
    out[1][0] = 0, out[1][1] = hi - n;
    return 2;
  };
  int64_t rx[3][2], ry[3][2];
  int nx = ranges(px.lo, px.hi, width_, rx), ny = ranges(py.lo, py.hi, height_, ry);
  // Whole periods count as one full range with a multiplicity.
  double mx[3] = {1, 1, 1}, my[3] = {1, 1, 1};
  if (px.whole > 0) rx[nx][0] = 0, rx[nx][1] = width_, mx[nx++] = double(px.whole);
  if (py.whole > 0) ry[ny][0] = 0, ry[ny][1] = height_, my[ny++] = double(py.whole);
  glm::dvec3 sum(0.0);
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j) {
      const glm::dvec3 s = sat(rx[i][1], ry[j][1]) - sat(rx[i][0], ry[j][1]) -
                           sat(rx[i][1], ry[j][0]) + sat(rx[i][0], ry[j][0]);
      sum += s * (mx[i] * my[j]);
    }
  return sum;
}

glm::vec3 Texture::mean(glm::vec2 lo, glm::vec2 hi) const {
  if (width_ == 0 || height_ == 0) return glm::vec3(0.8f);
  for (int a = 0; a < 2; ++a)  // non-finite coordinates read the texture's mean
    if (!std::isfinite(lo[a]) || !std::isfinite(hi[a]) || hi[a] - lo[a] > 1e6f) return mean();
  // Texel i covers [i, i + 1) in texel units; the box covers every texel it
  // touches, at least one on each axis, weighted by whole texels.
  auto texelRange = [](float a0, float a1, int n, int64_t& t0, int64_t& t1) {
    t0 = int64_t(std::floor(double(a0) * n));
    t1 = std::max(t0 + 1, int64_t(std::ceil(double(a1) * n)));
  };
  int64_t x0, x1, y0, y1;
  texelRange(lo.x, hi.x, width_, x0, x1);
  texelRange(lo.y, hi.y, height_, y0, y1);
  const double count = double(x1 - x0) * double(y1 - y0);
  return glm::vec3(boxSum(x0, x1, y0, y1) / count);
}

glm::vec3 Texture::mean() const {
  if (width_ == 0 || height_ == 0) return glm::vec3(0.8f);
  return glm::vec3(sat(width_, height_) / (double(width_) * double(height_)));
}

std::filesystem::path materialTexturePath(const Scene& scene, const Material& material) {
  if (material.baseColorTexture.empty() || material.baseColorImage) return {};
  const std::filesystem::path p(material.baseColorTexture);
  if (p.is_absolute()) return p;
  std::error_code ec;
  for (const auto& source : scene.sources) {
    const auto candidate = source.parent_path() / p;
    if (std::filesystem::exists(candidate, ec)) return candidate;
  }
  return scene.sources.empty() ? p : scene.sources.front().parent_path() / p;
}

std::vector<std::optional<Texture>> loadMaterialTextures(const Scene& scene,
                                                         std::vector<std::string>& warnings) {
  std::vector<std::optional<Texture>> textures(scene.materials.size());
  for (size_t m = 0; m < scene.materials.size(); ++m) {
    const Material& material = scene.materials[m];
    if (material.baseColorTexture.empty()) continue;
    std::string error, where;
    if (material.baseColorImage) {
      textures[m] = Texture::decode(*material.baseColorImage, error);
      where = fmt::format(
          "{} (inside {})", material.baseColorTexture,
          scene.sources.empty() ? std::string("the scene file") : scene.sources.front().string());
    } else {
      const auto file = materialTexturePath(scene, material);
      textures[m] = Texture::load(file, error);
      where = file.string();
    }
    if (!textures[m]) {
      warnings.push_back(fmt::format("material {}: texture {}: {}; its diffuse colour stays",
                                     material.name, where, error));
      spdlog::warn("{}", warnings.back());
    }
  }
  return textures;
}

}  // namespace vistream
