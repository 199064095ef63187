#include "client/render/render_geometry.h"

#include <algorithm>
#include <cmath>

#include "common/core/cpu_dispatch.h"
#include "common/light/lighting_cache.h"

namespace vistream {

glm::u8vec3 shadeTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                          const glm::vec3& diffuse) {
  const glm::vec3 n = glm::cross(b - a, c - a);
  const float len = glm::length(n);
  const float lambert = len > 0.0f ? std::abs(glm::dot(n / len, defaultSunDirection())) : 0.0f;
  return encodeColour(diffuse * (0.3f + 0.7f * lambert));
}

glm::u8vec3 RenderGeometry::background(const glm::vec3& eye, const glm::vec3& dir) const {
  return Backdrop{sky, ground, haze}.along(eye, dir, groundY);
}

VISTREAM_AVX2_CLONES void RenderGeometry::shadeBackground(const glm::vec3& eye,
                                                          const glm::vec3& first,
                                                          const glm::vec3& step, int count,
                                                          uint8_t* out) const {
  const bool hasGround = groundY && eye.y > *groundY;
  const float height = hasGround ? eye.y - *groundY : 0.0f;
  const float inverseScale = haze.scale > 0.0f ? 1.0f / haze.scale : 0.0f;
  const glm::vec3 skyColour(sky), groundColour(ground), hazeColour = haze.colour;
  // Chunks in passes the compiler vectorizes: each pixel's ground fade
  // (sky pixels take 0 and are overwritten), then the bytes. Each pass
  // computes what background() does.
  constexpr int kChunk = 64;
  float fade[kChunk];
  uint8_t below[kChunk];
  for (int k0 = 0; k0 < count; k0 += kChunk) {
    const int m = std::min(kChunk, count - k0);
    for (int k = 0; k < m; ++k) {
      const glm::vec3 dir = first + float(k0 + k) * step;
      const bool down = hasGround && dir.y < 0.0f;
      const float distance = height / (down ? -dir.y : 1.0f) * std::sqrt(glm::dot(dir, dir));
      fade[k] = oneMinusExpNeg(std::max(0.0f, distance) * inverseScale);
      below[k] = down ? 1 : 0;
    }
    for (int a = 0; a < 3; ++a) {
      const float g0 = groundColour[a], dg = hazeColour[a] - groundColour[a];
      const uint8_t skyByte = uint8_t(skyColour[a]);
      uint8_t* o = out + 3 * k0 + a;
      for (int k = 0; k < m; ++k) o[3 * k] = below[k] ? toByte(g0 + dg * fade[k]) : skyByte;
    }
  }
}

EyeTriangle EyeTriangle::of(const FlatTriangles& triangles, size_t t, const glm::vec3& eye) {
  const glm::vec3 a = triangles.vertex(t, 0);
  const glm::vec3 e1 = triangles.vertex(t, 1) - a, e2 = triangles.vertex(t, 2) - a;
  const glm::vec3 s = eye - a;
  EyeTriangle e;
  e.normal = glm::cross(e2, e1);
  e.toU = glm::cross(e2, s);
  e.toV = glm::cross(s, e1);
  e.along = glm::dot(e2, e.toV);
  e.centreDistance = glm::length(a + (e1 + e2) / 3.0f - eye);
  return e;
}

glm::u8vec3 RenderGeometry::colourAlong(size_t t, const EyeTriangle& seen,
                                        const glm::vec3& dir) const {
  const float det = glm::dot(dir, seen.normal);
  if (!(std::abs(det) > 0.0f))  // seen edge-on: the centre, at its distance
    return colourAt(t, 1.0f / 3.0f, 1.0f / 3.0f, seen.centreDistance);
  const float inv = 1.0f / det;
  const float u = glm::dot(dir, seen.toU) * inv, v = glm::dot(dir, seen.toV) * inv;
  return colourAt(t, u, v, std::abs(seen.along * inv) * glm::length(dir));
}

VISTREAM_AVX2_CLONES void RenderGeometry::shadeSpan(size_t t, const EyeTriangle& seen,
                                                    const glm::vec3& first, const glm::vec3& step,
                                                    int count, uint8_t* out) const {
  const glm::u8vec3* grid = lighting.colours.data() + lighting.first[t];
  const uint32_t level = lighting.level[t];
  const float inverseScale = haze.scale > 0.0f ? 1.0f / haze.scale : 0.0f;
  // Chunks of pixels in passes the compiler vectorizes, but for the lookups
  // in grids finer than one cell: the barycentrics (clamped as
  // LightingGrid::interpolate clamps them) and the haze, the colours, then
  // the hazed bytes. Each pass computes what colourAlong does.
  // Everything a pixel reads, in locals (no loads under a condition).
  const glm::vec3 normal = seen.normal, toU = seen.toU, toV = seen.toV;
  const float along = seen.along, centre = seen.centreDistance;
  constexpr int kChunk = 64;
  float us[kChunk], vs[kChunk], fade[kChunk], rgb[3][kChunk], weight[3][kChunk];
  int corner[3][kChunk];
  for (int k0 = 0; k0 < count; k0 += kChunk) {
    const int m = std::min(kChunk, count - k0);
    for (int k = 0; k < m; ++k) {
      const glm::vec3 dir = first + float(k0 + k) * step;
      const float det = glm::dot(dir, normal);
      const bool edgeOn = !(std::abs(det) > 0.0f);  // the centre, at its distance
      const float inv = 1.0f / (edgeOn ? 1.0f : det);
      const float u0 = glm::dot(dir, toU) * inv, v0 = glm::dot(dir, toV) * inv;
      const float d0 = std::abs(along * inv) * std::sqrt(glm::dot(dir, dir));
      float u = edgeOn ? 1.0f / 3.0f : u0, v = edgeOn ? 1.0f / 3.0f : v0;
      LightingGrid::clampBarycentrics(u, v);
      us[k] = u;
      vs[k] = v;
      fade[k] = oneMinusExpNeg(std::max(0.0f, edgeOn ? centre : d0) * inverseScale);
    }
    if (level == 1) {
      for (int a = 0; a < 3; ++a) {
        const float c0 = float(grid[0][a]), c1 = float(grid[1][a]), c2 = float(grid[2][a]);
        for (int k = 0; k < m; ++k)
          rgb[a][k] = c0 * (1.0f - us[k] - vs[k]) + c1 * us[k] + c2 * vs[k];
      }
    } else {
      // LightingGrid::interpolate in two passes: each pixel's three grid
      // points and weights (no branches), then the gathers.
      const int n = int(level);
      const float nf = float(level);
      for (int k = 0; k < m; ++k) {
        const float x = us[k] * nf, y = vs[k] * nf;
        const int j = std::min(int(y), n - 1);
        int i = std::min(int(x), n - 1);
        i -= i + j > n - 1 ? 1 : 0;
        const float fx = x - float(i), fy = y - float(j);
        const bool upper = fx + fy > 1.0f && i + j + 2 <= n;
        const int row0 = j * (n + 1) - j * (j - 1) / 2, row1 = row0 + n + 1 - j;  // rows j, j + 1
        corner[0][k] = upper ? row1 + i + 1 : row0 + i;
        corner[1][k] = upper ? row1 + i : row0 + i + 1;
        corner[2][k] = upper ? row0 + i + 1 : row1 + i;
        weight[0][k] = upper ? fx + fy - 1.0f : 1.0f - fx - fy;
        weight[1][k] = upper ? 1.0f - fx : fx;
        weight[2][k] = upper ? 1.0f - fy : fy;
      }
      for (int a = 0; a < 3; ++a)
        for (int k = 0; k < m; ++k)
          rgb[a][k] = float(grid[corner[0][k]][a]) * weight[0][k] +
                      float(grid[corner[1][k]][a]) * weight[1][k] +
                      float(grid[corner[2][k]][a]) * weight[2][k];
    }
    for (int a = 0; a < 3; ++a) {
      const float h = haze.colour[a];
      uint8_t* o = out + 3 * k0 + a;
      for (int k = 0; k < m; ++k) {
        const float c = rgb[a][k] + (h - rgb[a][k]) * fade[k];
        o[3 * k] = toByte(c);
      }
    }
  }
}

void appendTriangle(RenderGeometry& to, const FlatTriangles& from, const LightingGrid& lighting,
                    size_t t) {
  for (int k = 0; k < 3; ++k) {
    to.triangles.positions.push_back(from.vertex(t, k));
    to.bounds.extend(from.vertex(t, k));
  }
  to.triangles.faceIds.push_back(from.faceIds[t]);
  to.triangles.objectIds.push_back(from.objectIds[t]);
  to.triangles.degenerate.push_back(from.degenerate[t]);
  to.lighting.appendFrom(lighting, t);
}

void setBackdrop(RenderGeometry& g, const Backdrop& backdrop) {
  g.sky = backdrop.sky;
  g.ground = backdrop.ground;
  g.haze = backdrop.haze;
}

RenderGeometry renderGeometryFromScene(const Scene& scene, const LightingOptions& options,
                                       const std::filesystem::path& lightingCache) {
  RenderGeometry g;
  g.triangles = flattenScene(scene, /*staticOnly=*/true);
  SceneLighting lit = lightScene(scene, g.triangles, options, lightingCache);
  setBackdrop(g, lit.backdrop);
  g.lighting = std::move(lit.load.grid);
  for (size_t t = 0; t < g.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) g.bounds.extend(g.triangles.vertex(t, k));
  return g;
}

}  // namespace vistream
