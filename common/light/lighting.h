// Prelit colour that varies across a triangle: a small grid of colours per
// triangle, baked once per scene from its materials, the environment's light,
// a sun with hard shadows and ambient occlusion, then looked up by
// barycentrics in every renderer (OpenGL, the software rasterizer, the ray
// caster, the image cache), so a point has one colour whichever draws it.
//
// The grid: triangle (a, b, c) at level n >= 1 has a lighting point at every
// barycentric (u, v) = (i / n, j / n) with i + j <= n, at a + u (b - a) +
// v (c - a): (n + 1)(n + 2) / 2 points, n = ceil(longest edge / spacing)
// capped at maxLevel. A point's colour is interpolated linearly inside the
// grid's small triangle holding (u, v) (colourAt). Large faces are thereby
// subdivided for lighting only: triangles, face IDs and every visibility
// result stay as they were.
//
// Light at a point p with normal n (the triangle's winding normal, as glTF
// and OBJ define its front; the back shows the same colour):
//   colour = albedo * (ambient * E(n) / E_up * ao + sun * max(0, n . L) * lit)
// E is the environment's irradiance (environment_light.h), E_up its
// luminance on an up-facing surface (so an open, white, up-facing surface
// gets `ambient` from the sky whatever the HDR image's units), ao the share
// of cosine-weighted rays from p that travel aoDistance unblocked (Embree),
// and lit whether a ray towards the sun escapes. The result is encoded as 8-bit
// sRGB-like values (gamma 2.2): the colours renderers read.
//
// Albedo: the material's diffuse colour times its base-colour texture's mean
// over the point's share of the triangle (texture.h: a box of the grid's
// spacing in texture coordinates around the point). Faces their source gave
// no material (Material::unassigned, e.g. a city model's bare OBJ) take a
// colour by orientation, as city viewers colour roof and wall surfaces: roofs
// (normal within 45 degrees of up) tile red, walls light stone, undersides grey.
//
// Buried points: a point whose every ambient-occlusion ray is blocked (a
// ground triangle running under a building, a wall sunk into the ground) is
// seen from nowhere, so its colour would only darken its visible neighbours
// through interpolation; it takes the mean colour of the grid points around
// it that are open.
//
// Thread safety: a LightingGrid is immutable once baked; bakeLighting runs
// in parallel (TBB) and is deterministic (each point's rays are seeded by
// the point, so a run gives the same bytes on any thread count).
#pragma once

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/light/environment_light.h"
#include "common/raycast/ray_query.h"
#include "common/scene/scene.h"

namespace vistream {

// The default sun (unit, local frame): high in the south-east (Environment's).
glm::vec3 defaultSunDirection();
// A linear colour in [0, 1] as 8-bit values (gamma 2.2, rounded, clamped).
glm::u8vec3 encodeColour(const glm::vec3& linear);

struct LightingGrid {
  std::vector<uint32_t> first;       // per triangle: its first colour in `colours`
  std::vector<uint8_t> level;        // per triangle: n >= 1
  std::vector<glm::u8vec3> colours;  // every triangle's points, row by row (j), then by i

  size_t size() const { return level.size(); }
  static constexpr uint32_t pointsOf(uint32_t n) { return (n + 1) * (n + 2) / 2; }
  // Index of point (i, j) within a grid of level n (i + j <= n).
  static constexpr uint32_t pointIndex(uint32_t n, uint32_t i, uint32_t j) {
    return j * (n + 1) - j * (j - 1) / 2 + i;
  }
  // Appends one triangle's grid (colours.size() == pointsOf(n)).
  void append(uint32_t n, const glm::u8vec3* colours, size_t count);
  // One flat colour for a triangle (level 1, three equal corners).
  void appendFlat(glm::u8vec3 c);
  // Appends a copy of triangle t's grid of `from`.
  void appendFrom(const LightingGrid& from, size_t t);

  // Barycentrics clamped into the triangle (a hit on an edge may round out;
  // NaN gives 0), written with min and max so that pixel loops vectorize.
  static void clampBarycentrics(float& u, float& v) {
    u = std::min(std::max(0.0f, u), 1.0f);
    v = std::min(std::max(0.0f, v), 1.0f - u);
  }
  // The colour at barycentrics (u, v) of triangle t (weights of its vertices 1
  // and 2), interpolated within the grid, in 0..255 per channel (unrounded).
  glm::vec3 colourAt(size_t t, float u, float v) const {
    return interpolate(colours.data() + first[t], level[t], u, v);
  }
  // The same on one grid `g` of level n (inline: renderers call it per pixel).
  [[gnu::always_inline]] static glm::vec3 interpolate(const glm::u8vec3* g, uint32_t n, float u,
                                                      float v) {
    clampBarycentrics(u, v);
    auto at = [&](uint32_t a, uint32_t b) { return glm::vec3(g[pointIndex(n, a, b)]); };
    if (n == 1) return at(0, 0) * (1.0f - u - v) + at(1, 0) * u + at(0, 1) * v;
    const float x = u * float(n), y = v * float(n);
    // Cell (i, j): its lower triangle (i, j), (i + 1, j), (i, j + 1) always
    // exists, its upper one (i + 1, j + 1), (i, j + 1), (i + 1, j) when i + j
    // <= n - 2. A point on the grid's far edge (i + j = n) belongs to the
    // cell before it.
    uint32_t i = std::min(uint32_t(x), n - 1), j = std::min(uint32_t(y), n - 1);
    if (i + j > n - 1) --i;  // i + j <= x + y <= n, and j <= n - 1 gives i >= 1 here
    const float fx = x - float(i), fy = y - float(j);
    if (fx + fy > 1.0f && i + j + 2 <= n)
      return at(i + 1, j + 1) * (fx + fy - 1.0f) + at(i, j + 1) * (1.0f - fx) +
             at(i + 1, j) * (1.0f - fy);
    return at(i, j) * (1.0f - fx - fy) + at(i + 1, j) * fx + at(i, j + 1) * fy;
  }
  // The mean of a triangle's grid colours (for a one-colour summary).
  glm::u8vec3 meanColour(size_t t) const;
};

struct LightingOptions {
  float spacing = 8.0f;   // metres between lighting points on large faces
  uint32_t maxLevel = 8;  // at most 45 points a triangle
  // A triangle keeps the coarsest grid (a level dividing its own) that
  // reproduces all its points within this many 8-bit levels per channel.
  float tolerance = 4.0f;
  // Colours are rounded to multiples of this (and 255 kept): 4 changes a
  // colour by at most 2 levels and makes a streamed grid about a third
  // smaller (protocol: Geometry.lighting codes the multiples). 1: exact.
  uint32_t colourStep = 4;
  uint32_t aoRays = 48;     // per lighting point; 0 turns ambient occlusion off
  float aoDistance = 3.0f;  // metres a ray must travel to count as open
  float ambient = 0.7f;     // sky light on an open, up-facing white surface
  // The sun: the scene's (Environment::sunDirection, sunIntensity) unless set.
  std::optional<float> sunIntensity;      // 0: no sun
  std::optional<glm::vec3> sunDirection;  // towards the sun
  bool sunShadows = true;
};

struct LightingStats {
  uint64_t triangles = 0;
  uint64_t fullPoints = 0;  // lighting points computed
  uint64_t points = 0;      // kept after simplification (tolerance)
  uint64_t aoRays = 0, shadowRays = 0;
  double seconds = 0.0;
  double meanAo = 0.0;  // over every point
  uint32_t texturedMaterials = 0;
  std::vector<std::string> warnings;  // textures missing or unreadable
};

// The factor from the environment's irradiance to the bake's light: an open,
// up-facing white surface gets options.ambient from the sky.
float skyExposure(const EnvironmentLight& environment, const LightingOptions& options);
// The 8-bit colour of the sky near the horizon at that exposure (a uniform
// sky of radiance L gives irradiance pi L): the background and haze colour.
glm::u8vec3 horizonColour(const EnvironmentLight& environment, const LightingOptions& options);

// Bakes the grid of every triangle of `triangles` (a flattening of the
// scene's static objects, flattenScene(scene, true), whose ray queries `rays`
// answers). Progress on stderr when `progress` and stderr is a terminal.
LightingGrid bakeLighting(const Scene& scene, const FlatTriangles& triangles, const RayQuery& rays,
                          const EnvironmentLight& environment, const LightingOptions& options,
                          LightingStats* stats = nullptr, bool progress = false);

// The share of cosine-weighted rays from p (unit normal n) that travel
// `distance` unblocked: `count` rays, stratified and rotated by `seed`.
double ambientOcclusion(const RayQuery& rays, const glm::vec3& p, const glm::vec3& n,
                        uint32_t count, float distance, uint64_t seed);

// 1 - exp(-x) for x >= 0 (0 for x <= 0 or NaN) without a library call, so loops over pixels
// vectorize: exp(-x) = 2^n 2^f with n the integer nearest -x log2(e) and
// |f| <= 1/2, 2^f by its degree-7 Taylor polynomial. Off by less than 1e-6
// (a ten-thousandth of an 8-bit level in a haze); 1 beyond x = 87.
inline float oneMinusExpNeg(float x) {
  // NaN gives 0 (std::max(0, NaN) is 0), so the conversion to int below
  // always has a number in range.
  const float y = -std::min(std::max(0.0f, x), 87.0f) * 1.44269504f;  // in [-125.6, 0]
  const int n = int(y - 0.5f);                                        // nearest integer (y <= 0)
  const float f = (y - float(n)) * 0.693147181f;                      // e^f = 2^(y - n)
  const float p =
      1.0f + f * (1.0f + f * (0.5f + f * (1.0f / 6.0f +
                                          f * (1.0f / 24.0f +
                                               f * (1.0f / 120.0f +
                                                    f * (1.0f / 720.0f + f * (1.0f / 5040.0f)))))));
  return 1.0f - std::bit_cast<float>(uint32_t(n + 127) << 23) * p;
}

// Fades a colour (0..255 per channel) towards the horizon's colour with
// distance: c + (haze - c) * (1 - exp(-distance / scale)). The same in every
// renderer (the CPU ones by oneMinusExpNeg, the OpenGL shader by exp);
// scale 0 turns it off.
struct Haze {
  glm::vec3 colour{0.0f};  // 0..255
  float scale = 0.0f;      // metres

  float amount(float distance) const {
    return scale > 0.0f ? oneMinusExpNeg(std::max(0.0f, distance) * (1.0f / scale)) : 0.0f;
  }
  glm::vec3 apply(const glm::vec3& c, float distance) const {
    return c + (colour - c) * amount(distance);
  }
};
// Rounds a 0..255 colour to bytes (half up; clamped, so never negative).
inline uint8_t toByte(float c) {
  return uint8_t(std::min(std::max(0.0f, c), 255.0f) + 0.5f);
}
inline glm::u8vec3 toBytes(const glm::vec3& c) {
  return glm::u8vec3(toByte(c.r), toByte(c.g), toByte(c.b));
}

// What a renderer shows where no triangle is: the sky's colour near the
// horizon (horizonColour), an assumed ground plane's colour lit like an open,
// up-facing surface, and the haze towards the sky colour.
struct Backdrop {
  glm::u8vec3 sky{140, 180, 230};
  glm::u8vec3 ground{118, 112, 100};
  Haze haze;

  // What a ray from `eye` along `dir` meets when it hits no triangle: the
  // sky, or, looking down from above an assumed ground plane at local height
  // `groundY`, the ground, hazed by its distance.
  glm::u8vec3 along(const glm::vec3& eye, const glm::vec3& dir,
                    std::optional<float> groundY) const {
    if (!groundY || !(dir.y < 0.0f) || !(eye.y > *groundY)) return sky;
    const float distance = (eye.y - *groundY) / -dir.y * glm::length(dir);
    return toBytes(haze.apply(glm::vec3(ground), distance));
  }
};
Backdrop backdropOf(const Scene& scene, const EnvironmentLight& environment,
                    const LightingOptions& options = {});

}  // namespace vistream
