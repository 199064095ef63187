// A material's base-colour texture, reduced to what prelit per-vertex colour
// needs: the mean colour over a box of texture coordinates.
//
// Why means: a scene's colour lives at its lighting points (lighting.h), a
// few metres apart on large faces, while a texture varies per texel. A
// lighting point takes the mean of the texels under its share of the
// triangle (a box around its coordinates as wide as the grid's spacing), so
// a brick wall keeps its overall hue and a face that spans few texels takes
// their mean over the triangle; sampling single texels would alias instead.
// Means are exact box filters from a summed-area table, in linear colour
// (texels are sRGB), with the texture repeating outside [0, 1] as glTF's and
// OBJ's default wrap does.
//
// Thread safety: immutable after loading.
#pragma once

#include <cstdint>
#include <filesystem>
#include <glm/glm.hpp>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace vistream {

class Texture {
 public:
  // Decodes an image file (PNG, JPEG, TGA, BMP, ... as stb_image reads them),
  // or encoded image bytes (an image embedded in a glTF binary). On failure:
  // nothing, and `error` names the cause.
  static std::optional<Texture> load(const std::filesystem::path& file, std::string& error);
  static std::optional<Texture> decode(std::span<const uint8_t> bytes, std::string& error);
  // From linear RGB texels, row 0 at the top (v = 0 is the top row, as in glTF).
  static Texture fromLinear(int width, int height, std::vector<glm::vec3> texels);

  int width() const { return width_; }
  int height() const { return height_; }
  // Mean linear colour over the texture-coordinate box [lo, hi] (hi >= lo;
  // a box of zero size gives the texel under it), wrapping around.
  glm::vec3 mean(glm::vec2 lo, glm::vec2 hi) const;
  // Mean of the whole image.
  glm::vec3 mean() const;

 private:
  // Sum over texels [0, x) x [0, y) for x, y in [0, width] x [0, height].
  glm::dvec3 sat(int64_t x, int64_t y) const;
  // Sum over the texel box [x0, x1) x [y0, y1), any integers (wrapping).
  glm::dvec3 boxSum(int64_t x0, int64_t x1, int64_t y0, int64_t y1) const;

  int width_ = 0, height_ = 0;
  std::vector<glm::dvec3> table_;  // (width + 1) x (height + 1) summed-area table
};

// 8-bit sRGB to linear, per channel.
float srgbToLinear(uint8_t c);

struct Material;
struct Scene;

// Where a material's texture file is: its name when absolute, else beside
// the first of the scene's source files that has it. Empty for a material
// without a texture or with its image inside the scene file.
std::filesystem::path materialTexturePath(const Scene& scene, const Material& material);

// Every material's base-colour texture, decoded from the scene file's own
// bytes or from its file; nothing where a material has none. A texture that
// is missing or cannot be decoded adds a warning (naming the material and
// the file) to `warnings` and logs it: its material keeps its diffuse colour.
std::vector<std::optional<Texture>> loadMaterialTextures(const Scene& scene,
                                                         std::vector<std::string>& warnings);

}  // namespace vistream
