// The triangles a client holds, with the colours they are drawn in.
//
// Shading is prelit: every triangle carries a small grid of colours
// (common/light/lighting.h), baked once from its materials, the
// environment's light, the sun and ambient occlusion, and looked up by
// barycentrics. The OpenGL near field, the software rasterizer and the ray
// caster all read these bytes with the same interpolation and the same
// distance haze, so a far-field pixel and a near-field pixel of the same
// point are the same colour and the border does not show.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <vector>

#include "common/core/box.h"
#include "common/light/lighting.h"
#include "common/scene/scene.h"

namespace vistream {

// A flat colour for a triangle with no baked lighting (streamed faces until
// the wire carries their colours, test scenes): its material's diffuse colour
// times (ambient + diffuse * |n . L|) for the default sun.
glm::u8vec3 shadeTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                          const glm::vec3& diffuse);

// One triangle as seen from one eye: what turns a ray direction into the
// barycentrics and distance of the point it meets on the triangle's plane
// with three dot products (Moeller and Trumbore's test, its eye-dependent
// cross products done once), so a frame sets it up per triangle, not per pixel.
struct EyeTriangle {
  glm::vec3 normal{0.0f};       // (c - a) x (b - a): dir . normal is the determinant
  glm::vec3 toU{0.0f};          // (c - a) x (eye - a)
  glm::vec3 toV{0.0f};          // (eye - a) x (b - a)
  float along = 0.0f;           // (c - a) . toV: the distance numerator
  float centreDistance = 0.0f;  // for a triangle seen edge-on

  static EyeTriangle of(const FlatTriangles& triangles, size_t t, const glm::vec3& eye);
};

struct RenderGeometry {
  FlatTriangles triangles;           // local frame
  LightingGrid lighting;             // per triangle: its colours (lighting.h)
  Haze haze;                         // fading towards the horizon colour with distance
  glm::u8vec3 sky = Backdrop{}.sky;  // background for pixels that see nothing
  // An assumed ground plane (static_world.h) at this local height: pixels
  // that see nothing below the horizon show `ground` instead of the sky.
  std::optional<float> groundY;
  glm::u8vec3 ground = Backdrop{}.ground;
  // The background a ray from `eye` along `dir` meets when it hits no
  // triangle: the sky, or the assumed ground (hazed by its distance).
  glm::u8vec3 background(const glm::vec3& eye, const glm::vec3& dir) const;
  // background() for `count` pixels along first + k * step, written as RGB
  // bytes to out[3k..3k+2] (a loop that vectorizes).
  void shadeBackground(const glm::vec3& eye, const glm::vec3& first, const glm::vec3& step,
                       int count, uint8_t* out) const;
  // The colour of triangle t at barycentrics (u, v) seen from `distance` metres.
  glm::u8vec3 colourAt(size_t t, float u, float v, float distance) const {
    return toBytes(haze.apply(lighting.colourAt(t, u, v), distance));
  }
  // The same for the point where the ray from `eye` along `dir` meets
  // triangle t's plane (barycentrics computed here, as a rasterizer would).
  glm::u8vec3 colourAlong(size_t t, const glm::vec3& eye, const glm::vec3& dir) const {
    return colourAlong(t, EyeTriangle::of(triangles, t, eye), dir);
  }
  // The same with the triangle set up for the eye once (a frame's pixels).
  glm::u8vec3 colourAlong(size_t t, const EyeTriangle& seen, const glm::vec3& dir) const;
  // colourAlong for `count` pixels in a row that all see triangle t, along
  // directions first + k * step, written as RGB bytes to out[3k..3k+2]: the
  // same colours, without a call and a returned colour per pixel (the
  // software near field's inner loop).
  void shadeSpan(size_t t, const EyeTriangle& seen, const glm::vec3& first, const glm::vec3& step,
                 int count, uint8_t* out) const;
  Box3f bounds;

  size_t size() const { return triangles.size(); }
};

// Every triangle of the scene's static objects with its baked lighting
// (bakeLighting with `options`, the scene's environment light) and haze.
// The bake is read from or written to `lightingCache` (lighting_cache.h;
// empty: no cache).
RenderGeometry renderGeometryFromScene(const Scene& scene, const LightingOptions& options = {},
                                       const std::filesystem::path& lightingCache = {});
// Appends triangle t of `from` with its colours (`lighting`, parallel to
// `from`) to `to`, and grows its bounds.
void appendTriangle(RenderGeometry& to, const FlatTriangles& from, const LightingGrid& lighting,
                    size_t t);
// Takes the sky, ground and haze of a backdrop.
void setBackdrop(RenderGeometry& g, const Backdrop& backdrop);
// Recomputes bounds and gives every triangle one flat colour after
// `triangles` changed; `diffuse` gives a triangle's diffuse colour.
template <class DiffuseOf>
void recolour(RenderGeometry& g, DiffuseOf&& diffuse) {
  g.lighting = LightingGrid{};
  g.bounds = Box3f{};
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const glm::vec3 a = g.triangles.vertex(t, 0), b = g.triangles.vertex(t, 1),
                    c = g.triangles.vertex(t, 2);
    g.lighting.appendFlat(shadeTriangle(a, b, c, diffuse(t)));
    g.bounds.extend(a);
    g.bounds.extend(b);
    g.bounds.extend(c);
  }
}

}  // namespace vistream
