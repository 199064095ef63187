#include "common/light/lighting.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <memory>
#include <numbers>

#include "common/core/check.h"
#include "common/core/progress.h"
#include "common/core/random.h"
#include "common/core/tangent_frame.h"
#include "common/light/texture.h"

namespace vistream {
namespace {

float luminance(const glm::vec3& c) {
  return glm::dot(c, glm::vec3(0.2126f, 0.7152f, 0.0722f));
}

// A seed from a point's position, so points shared by neighbouring triangles
// (same position, same normal) get the same rays.
uint64_t pointSeed(const glm::vec3& p) {
  uint64_t h = 0;
  for (int a = 0; a < 3; ++a) {
    uint32_t bits;
    const float v = p[a] == 0.0f ? 0.0f : p[a];  // -0 and +0 alike
    std::memcpy(&bits, &v, 4);
    h = mixBits(h ^ bits);
  }
  return h;
}

// Offset of a ray's origin off a surface at p: above float rounding of the
// coordinates and of the hit test, far below any feature a lighting grid
// resolves.
float surfaceOffset(const glm::vec3& p) {
  const float m = std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)});
  return 2e-3f + 4e-6f * m;
}

// Per flattened static triangle: its material and texture coordinates.
struct SurfaceTable {
  std::vector<uint32_t> material;
  std::vector<std::array<glm::vec2, 3>> uv;
  std::vector<uint8_t> hasUv;
};

SurfaceTable surfacesOf(const Scene& scene) {
  SurfaceTable s;
  for (const Object& o : scene.objects) {
    if (o.dynamic) continue;
    const TriangleMesh& m = o.mesh;
    for (size_t t = 0; t < m.triangles.size(); ++t) {
      s.material.push_back(t < m.materials.size() ? m.materials[t] : 0u);
      std::array<glm::vec2, 3> uv{};
      bool has = !m.texcoords.empty();
      for (int k = 0; k < 3 && has; ++k) {
        const uint32_t v = m.triangles[t][k];
        if (v < m.texcoords.size())
          uv[size_t(k)] = m.texcoords[v];
        else
          has = false;
      }
      s.uv.push_back(uv);
      s.hasUv.push_back(has ? 1 : 0);
    }
  }
  return s;
}

// The albedo of a face without a material, by its orientation (lighting.h).
glm::vec3 orientationColour(const glm::vec3& n) {
  if (n.y > 0.7071f) return {0.42f, 0.17f, 0.12f};   // roofs: red tiles
  if (n.y < -0.7071f) return {0.45f, 0.45f, 0.45f};  // undersides
  return {0.72f, 0.64f, 0.52f};                      // walls: light stone
}

// Gives every buried point of a level-n grid (buried[k]) the mean of its open
// grid neighbours, spreading inwards until none is left (or none is open).
void fillBuried(glm::u8vec3* g, uint32_t n, std::vector<uint8_t>& buried) {
  const int di[6] = {1, -1, 0, 0, 1, -1}, dj[6] = {0, 0, 1, -1, -1, 1};
  for (bool changed = true; changed;) {
    changed = false;
    std::vector<std::pair<uint32_t, glm::u8vec3>> filled;
    for (uint32_t j = 0; j <= n; ++j)
      for (uint32_t i = 0; i + j <= n; ++i) {
        const uint32_t k = LightingGrid::pointIndex(n, i, j);
        if (!buried[k]) continue;
        glm::vec3 sum(0.0f);
        int count = 0;
        for (int e = 0; e < 6; ++e) {
          const int a = int(i) + di[e], b = int(j) + dj[e];
          if (a < 0 || b < 0 || a + b > int(n)) continue;
          const uint32_t m = LightingGrid::pointIndex(n, uint32_t(a), uint32_t(b));
          if (buried[m]) continue;
          sum += glm::vec3(g[m]);
          ++count;
        }
        if (count > 0) filled.emplace_back(k, toBytes(sum / float(count)));
      }
    for (const auto& [k, c] : filled) {
      g[k] = c;
      buried[k] = 0;
      changed = true;
    }
  }
}

// c rounded to the nearest multiple of `step` (255 where that passes 255).
glm::u8vec3 posterize(glm::u8vec3 c, uint32_t step) {
  if (step <= 1) return c;
  for (int a = 0; a < 3; ++a)
    c[a] = uint8_t(std::min<uint32_t>(255, (uint32_t(c[a]) + step / 2) / step * step));
  return c;
}

// The coarsest level m dividing n whose grid (every (n / m)-th point of the
// level-n grid g) reproduces every point of g within `tolerance` per channel.
uint32_t coarsestWithin(const glm::u8vec3* g, uint32_t n, float tolerance) {
  std::vector<glm::u8vec3> coarse;
  for (uint32_t m = 1; m < n; ++m) {
    if (n % m != 0) continue;
    const uint32_t k = n / m;
    coarse.resize(LightingGrid::pointsOf(m));
    for (uint32_t j = 0; j <= m; ++j)
      for (uint32_t i = 0; i + j <= m; ++i)
        coarse[LightingGrid::pointIndex(m, i, j)] = g[LightingGrid::pointIndex(n, k * i, k * j)];
    bool within = true;
    for (uint32_t j = 0; j <= n && within; ++j)
      for (uint32_t i = 0; i + j <= n && within; ++i) {
        const glm::vec3 c =
            LightingGrid::interpolate(coarse.data(), m, float(i) / float(n), float(j) / float(n));
        const glm::vec3 d = glm::abs(c - glm::vec3(g[LightingGrid::pointIndex(n, i, j)]));
        within = std::max({d.r, d.g, d.b}) <= tolerance;
      }
    if (within) return m;
  }
  return n;
}

}  // namespace

glm::vec3 defaultSunDirection() {
  return Environment{}.sunDirection;
}

glm::u8vec3 encodeColour(const glm::vec3& linear) {
  glm::u8vec3 out;
  for (int i = 0; i < 3; ++i) {
    const float c = std::isfinite(linear[i]) ? std::clamp(linear[i], 0.0f, 1.0f) : 0.0f;
    out[i] = uint8_t(std::lround(255.0f * std::pow(c, 1.0f / 2.2f)));
  }
  return out;
}

void LightingGrid::append(uint32_t n, const glm::u8vec3* c, size_t count) {
  VS_CHECK(n >= 1 && n <= 255);
  VS_CHECK_EQ(count, size_t(pointsOf(n)));
  first.push_back(uint32_t(colours.size()));
  level.push_back(uint8_t(n));
  colours.insert(colours.end(), c, c + count);
}

void LightingGrid::appendFlat(glm::u8vec3 c) {
  const glm::u8vec3 three[3] = {c, c, c};
  append(1, three, 3);
}

void LightingGrid::appendFrom(const LightingGrid& from, size_t t) {
  const uint32_t n = from.level[t];
  append(n, from.colours.data() + from.first[t], pointsOf(n));
}

glm::u8vec3 LightingGrid::meanColour(size_t t) const {
  const uint32_t count = pointsOf(level[t]);
  glm::vec3 sum(0.0f);
  for (uint32_t k = 0; k < count; ++k) sum += glm::vec3(colours[first[t] + k]);
  return toBytes(sum / float(count));
}

double ambientOcclusion(const RayQuery& rays, const glm::vec3& p, const glm::vec3& n,
                        uint32_t count, float distance, uint64_t seed) {
  if (count == 0) return 1.0;
  const TangentFrame frame = TangentFrame::around(n);
  const glm::vec3 &t = frame.t, &b = frame.b;
  const glm::vec3 org = p + n * surfaceOffset(p);
  // Stratified on a sqrt(count) x sqrt(count) grid of the unit square (the
  // remainder at random), rotated by the seed (Cranley-Patterson), then
  // mapped to the cosine-weighted hemisphere (Malley's method).
  const double r1 = unitInterval(mixBits(seed)),
               r2 = unitInterval(mixBits(seed ^ 0x5851f42d4c957f2dull));
  const uint32_t side = std::max<uint32_t>(1, uint32_t(std::sqrt(double(count))));
  std::vector<Ray> batch(count);
  for (uint32_t k = 0; k < count; ++k) {
    double s1, s2;
    if (k < side * side) {
      s1 = (double(k % side) + 0.5) / side;
      s2 = (double(k / side) + 0.5) / side;
    } else {
      s1 = unitInterval(mixBits(seed + 2 * k + 1));
      s2 = unitInterval(mixBits(seed + 2 * k + 2));
    }
    s1 = std::fmod(s1 + r1, 1.0);
    s2 = std::fmod(s2 + r2, 1.0);
    const double r = std::sqrt(s1), phi = 2.0 * double(std::numbers::pi_v<float>) * s2;
    const float x = float(r * std::cos(phi)), y = float(r * std::sin(phi));
    const float z = float(std::sqrt(std::max(0.0, 1.0 - s1)));
    batch[k] = Ray{org, t * x + b * y + n * z, 0.0f, distance};
  }
  std::vector<uint8_t> blocked(count);
  rays.occludedMany(batch, blocked);
  uint32_t open = 0;
  for (uint8_t o : blocked) open += o ? 0u : 1u;
  return double(open) / double(count);
}

float skyExposure(const EnvironmentLight& environment, const LightingOptions& options) {
  const float up = luminance(environment.irradiance(glm::vec3(0.0f, 1.0f, 0.0f)));
  return up > 0.0f && std::isfinite(up) ? options.ambient / up : 0.0f;
}

glm::u8vec3 horizonColour(const EnvironmentLight& environment, const LightingOptions& options) {
  return encodeColour(environment.horizonRadiance() *
                      (std::numbers::pi_v<float> * skyExposure(environment, options)));
}

Backdrop backdropOf(const Scene& scene, const EnvironmentLight& environment,
                    const LightingOptions& options) {
  Backdrop b;
  b.sky = horizonColour(environment, options);
  b.haze = Haze{glm::vec3(b.sky), scene.environment.hazeDistance};
  const float sunIntensity = options.sunIntensity.value_or(scene.environment.sunIntensity);
  const glm::vec3 sun = options.sunDirection.value_or(scene.environment.sunDirection);
  const float sunLight = sunIntensity * std::max(0.0f, glm::normalize(sun).y);
  b.ground = encodeColour(glm::vec3(0.30f, 0.28f, 0.25f) * (options.ambient + sunLight));
  return b;
}

LightingGrid bakeLighting(const Scene& scene, const FlatTriangles& triangles, const RayQuery& rays,
                          const EnvironmentLight& environment, const LightingOptions& options,
                          LightingStats* stats, bool progress) {
  const auto start = std::chrono::steady_clock::now();
  VS_CHECK(options.spacing > 0.0f && options.maxLevel >= 1 && options.maxLevel <= 255);
  VS_CHECK(options.colourStep >= 1 && options.colourStep <= 16 &&
           (options.colourStep & (options.colourStep - 1)) == 0);
  const size_t count = triangles.size();
  const SurfaceTable surfaces = surfacesOf(scene);
  VS_CHECK_EQ(surfaces.material.size(), count);

  // Textures, once per material.
  LightingStats local;
  const std::vector<std::optional<Texture>> textures = loadMaterialTextures(scene, local.warnings);
  for (const auto& texture : textures) local.texturedMaterials += texture.has_value();

  // Levels and offsets, then every triangle's points in parallel.
  LightingGrid grid;
  grid.level.resize(count);
  grid.first.resize(count);
  uint64_t points = 0;
  for (size_t t = 0; t < count; ++t) {
    const glm::vec3 a = triangles.vertex(t, 0), b = triangles.vertex(t, 1),
                    c = triangles.vertex(t, 2);
    const float longest = std::max({glm::length(b - a), glm::length(c - b), glm::length(a - c)});
    const float ratio = std::isfinite(longest) ? longest / options.spacing : 1.0f;
    const uint32_t n =
        std::clamp<uint32_t>(uint32_t(std::ceil(std::min(ratio, 255.0f))), 1u, options.maxLevel);
    grid.level[t] = uint8_t(n);
    grid.first[t] = uint32_t(points);
    points += LightingGrid::pointsOf(n);
  }
  VS_CHECK_LE(points, uint64_t(std::numeric_limits<uint32_t>::max()));
  grid.colours.resize(size_t(points));

  const glm::vec3 sun =
      glm::normalize(options.sunDirection.value_or(scene.environment.sunDirection));
  const float sunIntensity = options.sunIntensity.value_or(scene.environment.sunIntensity);
  const bool sunOn = sunIntensity > 0.0f && std::isfinite(sun.x);
  const float skyScale = skyExposure(environment, options);
  std::atomic<uint64_t> shadowRays{0};
  std::vector<double> aoSum(count, 0.0);
  std::vector<uint8_t> chosen(count, 1);
  std::unique_ptr<ProgressBar> bar =
      progress ? std::make_unique<ProgressBar>("lighting", count) : nullptr;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 64), [&](const auto& range) {
    for (size_t t = range.begin(); t != range.end(); ++t) {
      const glm::vec3 a = triangles.vertex(t, 0), b = triangles.vertex(t, 1),
                      c = triangles.vertex(t, 2);
      glm::vec3 n = glm::cross(b - a, c - a);
      const float len = glm::length(n);
      n = len > 0.0f && std::isfinite(len) ? n / len : glm::vec3(0.0f, 1.0f, 0.0f);
      const uint32_t material = surfaces.material[t];
      const glm::vec3 diffuse = material >= scene.materials.size() ? glm::vec3(0.8f)
                                : scene.materials[material].unassigned
                                    ? orientationColour(n)
                                    : scene.materials[material].diffuse;
      const Texture* texture = material < textures.size() && textures[material] && surfaces.hasUv[t]
                                   ? &*textures[material]
                                   : nullptr;
      const uint32_t level = grid.level[t];
      const auto& uv = surfaces.uv[t];
      glm::vec2 uvLo = glm::min(uv[0], glm::min(uv[1], uv[2]));
      glm::vec2 uvHi = glm::max(uv[0], glm::max(uv[1], uv[2]));
      const glm::vec2 footprint = (uvHi - uvLo) / float(level);
      const glm::vec3 sky = environment.irradiance(n) * skyScale;
      const glm::vec3 centroid = (a + b + c) / 3.0f;
      const float sunCos = sunOn ? std::max(0.0f, glm::dot(n, sun)) : 0.0f;
      glm::u8vec3* out = grid.colours.data() + grid.first[t];
      std::vector<uint8_t> buried(LightingGrid::pointsOf(level), 0);
      for (uint32_t j = 0; j <= level; ++j)
        for (uint32_t i = 0; i + j <= level; ++i) {
          const float u = float(i) / float(level), v = float(j) / float(level);
          const glm::vec3 p = a + u * (b - a) + v * (c - a);
          glm::vec3 albedo = diffuse;
          if (texture) {
            const glm::vec2 at = uv[0] + u * (uv[1] - uv[0]) + v * (uv[2] - uv[0]);
            albedo *= level == 1 ? texture->mean(uvLo, uvHi)
                                 : texture->mean(at - 0.5f * footprint, at + 0.5f * footprint);
          }
          // Rays leave from just inside the triangle: a point on its edge
          // may lie in the plane of a wall meeting it there.
          const glm::vec3 in = centroid - p;
          const float inLength = glm::length(in), step = surfaceOffset(p);
          const glm::vec3 q = inLength > 2.0f * step ? p + in * (step / inLength) : p;
          const double ao = ambientOcclusion(rays, q, n, options.aoRays, options.aoDistance,
                                             pointSeed(p) ^ mixBits(pointSeed(n)));
          aoSum[t] += ao;
          buried[LightingGrid::pointIndex(level, i, j)] = options.aoRays > 0 && ao == 0.0;
          float lit = 0.0f;
          if (sunCos > 0.0f) {
            lit = 1.0f;
            if (options.sunShadows) {
              const Ray shadow{q + n * surfaceOffset(q), sun, 0.0f,
                               std::numeric_limits<float>::infinity()};
              lit = rays.occluded(shadow) ? 0.0f : 1.0f;
              shadowRays.fetch_add(1, std::memory_order_relaxed);
            }
          }
          const glm::vec3 light = sky * float(ao) + glm::vec3(sunIntensity * sunCos * lit);
          out[LightingGrid::pointIndex(level, i, j)] = encodeColour(albedo * light);
        }
      fillBuried(out, level, buried);
      for (uint32_t k = 0; k < LightingGrid::pointsOf(level); ++k)
        out[k] = posterize(out[k], options.colourStep);
      chosen[t] = uint8_t(coarsestWithin(out, level, options.tolerance));
      if (bar) bar->advance();
    }
  });
  if (bar) bar->finish();

  // Each triangle keeps the coarsest grid that stays within the tolerance:
  // its points are among the full grid's, moved to the front of its slot.
  LightingGrid kept;
  kept.level.reserve(count);
  kept.first.reserve(count);
  uint64_t keptPoints = 0;
  for (size_t t = 0; t < count; ++t) keptPoints += LightingGrid::pointsOf(chosen[t]);
  kept.colours.reserve(size_t(keptPoints));
  std::vector<glm::u8vec3> coarse;
  for (size_t t = 0; t < count; ++t) {
    const uint32_t n = grid.level[t], m = chosen[t], k = n / m;
    const glm::u8vec3* full = grid.colours.data() + grid.first[t];
    coarse.resize(LightingGrid::pointsOf(m));
    for (uint32_t j = 0; j <= m; ++j)
      for (uint32_t i = 0; i + j <= m; ++i)
        coarse[LightingGrid::pointIndex(m, i, j)] = full[LightingGrid::pointIndex(n, k * i, k * j)];
    kept.append(m, coarse.data(), coarse.size());
  }
  local.fullPoints = points;
  points = keptPoints;
  grid = std::move(kept);

  local.triangles = count;
  local.points = points;
  local.aoRays = local.fullPoints * options.aoRays;
  local.shadowRays = shadowRays.load();
  double ao = 0.0;
  for (double s : aoSum) ao += s;
  local.meanAo = local.fullPoints ? ao / double(local.fullPoints) : 1.0;
  local.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (stats) *stats = std::move(local);
  return grid;
}

}  // namespace vistream
