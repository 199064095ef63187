// Open land under open sky: rolling hills in the middle, mountains toward the
// border, a scattering of trees and rocks. The scene for the far-field side
// of Wimmer's thesis (chapter 4: horizon tracing and the opacity buffer pay
// off where much of the screen is sky), and the counterpart of the densely
// occluded cities.
//
// Heightfield: 256 x 256 grid cells of 15.625 m over 4 km x 4 km centred on
// the origin, Y up, metres, each cell two triangles facing up (triangles, not
// quads: a heightfield quad is not planar, and an OBJ loader could split it
// along the other diagonal). Height is the sum of
//  - hills: value-noise fBm, 40 m amplitude, 700 m base wavelength, 4
//    octaves; tuned on seeds 1-8 so that slopes within 600 m of the centre
//    stay below 30% (walkable; the steepest there was 19%);
//  - mountains: ridged noise of 120-500 m under an envelope that rises from
//    900 m to 1800 m from the centre, so the border is ringed by steep peaks.
// Nothing covers the land from above: no ceiling, no overhangs, and no object
// within 60 m of the centre.
//
// Object order: 8 x 8 chunks "terrain_RR_CC" (row R along z from -Z, column C
// along x from -X; 32 x 32 cells, 2,048 triangles each, in grass, rock or snow
// by mean height), then "tree_NNNN" (trunk and crown boxes) and "rock_NNN"
// (a turned box), each sunk into the ground below its lowest corner.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>
#include <vector>

#include "common/generate/generate.h"
#include "common/generate/polygon_builder.h"
#include "common/generate/random.h"

namespace vistream {
namespace {

using generate_detail::addUprightBox;
using generate_detail::makeObject;
using generate_detail::mixBits;
using generate_detail::SceneRandom;

constexpr int kCells = 256;       // grid cells per side
constexpr double kSize = 4000.0;  // metres per side
constexpr double kCell = kSize / kCells;
constexpr int kChunks = 8;  // objects per side
constexpr int kChunkCells = kCells / kChunks;
constexpr int kTrees = 300;
constexpr int kRocks = 80;

// Material indices, scoped so that no other generator's names meet them.
struct TerrainMaterial {
  enum : uint32_t { kGrass, kRock, kSnow, kFoliage, kStone };
};

std::vector<Material> terrainMaterials() {
  const auto material = &Material::diffuseColour;
  return {material("grass", {0.30f, 0.45f, 0.20f}), material("rock", {0.45f, 0.42f, 0.38f}),
          material("snow", {0.92f, 0.93f, 0.95f}), material("foliage", {0.16f, 0.32f, 0.12f}),
          material("stone", {0.52f, 0.50f, 0.47f})};
}

double smoothstep(double edge0, double edge1, double x) {
  const double t = std::clamp((x - edge0) / (edge1 - edge0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// Value noise: a hashed value in [-1, 1] at each integer lattice point,
// interpolated with the quintic fade (C2 continuous, so no creases).
class ValueNoise {
 public:
  explicit ValueNoise(uint64_t seed) : seed_(mixBits(seed)) {}

  double operator()(double x, double z, int octave) const {
    const double fx = std::floor(x), fz = std::floor(z);
    const auto ix = int64_t(fx), iz = int64_t(fz);
    const double tx = fade(x - fx), tz = fade(z - fz);
    const double a = lattice(ix, iz, octave), b = lattice(ix + 1, iz, octave);
    const double c = lattice(ix, iz + 1, octave), d = lattice(ix + 1, iz + 1, octave);
    return (a + (b - a) * tx) + ((c + (d - c) * tx) - (a + (b - a) * tx)) * tz;
  }

 private:
  static double fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }

  double lattice(int64_t ix, int64_t iz, int octave) const {
    const uint64_t h = mixBits(seed_ ^ mixBits(uint64_t(ix) * 0x9e3779b97f4a7c15ull ^
                                               uint64_t(iz) * 0xc2b2ae3d27d4eb4full ^
                                               uint64_t(octave) * 0x165667b19e3779f9ull));
    return double(h >> 11) * 0x1.0p-52 - 1.0;
  }

  uint64_t seed_;
};

class Landscape {
 public:
  explicit Landscape(uint64_t seed) : noise_(seed) {}

  double height(double x, double z) const {
    // Hills: fBm normalised to +-1, then 40 m.
    double hills = 0.0, amplitude = 1.0, total = 0.0, frequency = 1.0 / 700.0;
    for (int o = 0; o < 4; ++o) {
      hills += amplitude * noise_(x * frequency, z * frequency, o);
      total += amplitude;
      amplitude *= 0.4;
      frequency *= 2.0;
    }
    hills = 40.0 * hills / total;

    // Mountains: ridged noise (sharp crests where the noise crosses zero).
    const double envelope = smoothstep(900.0, 1800.0, std::sqrt(x * x + z * z));
    if (envelope <= 0.0) return hills;
    double ridges = 0.0;
    amplitude = 1.0;
    total = 0.0;
    frequency = 1.0 / 500.0;
    for (int o = 0; o < 5; ++o) {
      const double ridge = 1.0 - std::abs(noise_(x * frequency, z * frequency, 10 + o));
      ridges += amplitude * ridge * ridge;
      total += amplitude;
      amplitude *= 0.5;
      frequency *= 2.0;
    }
    return hills + envelope * (120.0 + 380.0 * ridges / total);
  }

 private:
  ValueNoise noise_;
};

}  // namespace

PolygonScene generateTerrain(uint64_t seed) {
  SceneRandom random(seed);
  const Landscape landscape(seed);
  PolygonScene scene;
  scene.name = "terrain";
  scene.materials = terrainMaterials();

  // Heights at the grid vertices, shared by the chunks and by object placement.
  const int n = kCells + 1;
  auto coordinate = [](int i) { return -0.5 * kSize + i * kCell; };
  std::vector<double> heights(size_t(n) * size_t(n));
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      heights[size_t(j) * size_t(n) + size_t(i)] = landscape.height(coordinate(i), coordinate(j));
  auto heightAt = [&](int i, int j) { return heights[size_t(j) * size_t(n) + size_t(i)]; };

  for (int cj = 0; cj < kChunks; ++cj) {
    for (int ci = 0; ci < kChunks; ++ci) {
      PolygonObject chunk =
          makeObject(fmt::format("terrain_{:02d}_{:02d}", cj, ci), TerrainMaterial::kGrass);
      const int i0 = ci * kChunkCells, j0 = cj * kChunkCells, m = kChunkCells + 1;
      double sum = 0.0;
      for (int j = 0; j < m; ++j)
        for (int i = 0; i < m; ++i) {
          const double h = heightAt(i0 + i, j0 + j);
          chunk.vertices.emplace_back(coordinate(i0 + i), h, coordinate(j0 + j));
          sum += h;
        }
      for (int j = 0; j < kChunkCells; ++j)
        for (int i = 0; i < kChunkCells; ++i) {
          const auto v00 = uint32_t(j * m + i), v10 = v00 + 1, v01 = v00 + uint32_t(m),
                     v11 = v01 + 1;
          chunk.faces.push_back({v00, v01, v11});  // both wound to face up
          chunk.faces.push_back({v00, v11, v10});
        }
      const double mean = sum / double(m * m);
      chunk.material = mean < 60.0
                           ? TerrainMaterial::kGrass
                           : (mean < 300.0 ? TerrainMaterial::kRock : TerrainMaterial::kSnow);
      scene.objects.push_back(std::move(chunk));
    }
  }

  // Placement: the cell under (x, z), its lowest corner and its slope.
  struct Ground {
    double lowest;
    double slope;  // rise over run, the steeper of the two axes
  };
  auto groundAt = [&](double x, double z) {
    const int i = std::clamp(int((x + 0.5 * kSize) / kCell), 0, kCells - 1);
    const int j = std::clamp(int((z + 0.5 * kSize) / kCell), 0, kCells - 1);
    const double a = heightAt(i, j), b = heightAt(i + 1, j), c = heightAt(i, j + 1),
                 d = heightAt(i + 1, j + 1);
    const double sx = std::max(std::abs(b - a), std::abs(d - c)) / kCell;
    const double sz = std::max(std::abs(c - a), std::abs(d - b)) / kCell;
    return Ground{std::min({a, b, c, d}), std::max(sx, sz)};
  };
  // Lowest grid height under a footprint of the given radius around (x, z).
  auto lowestUnder = [&](double x, double z, double radius) {
    double lowest = groundAt(x, z).lowest;
    for (const double dx : {-radius, radius})
      for (const double dz : {-radius, radius})
        lowest = std::min(lowest, groundAt(x + dx, z + dz).lowest);
    return lowest;
  };
  auto placeOnGentleGround = [&](double rMin, double rMax, double maxSlope, glm::dvec2& at) {
    for (int attempt = 0; attempt < 100; ++attempt) {
      const double angle = random.uniform(0.0, 2.0 * std::numbers::pi);
      const double r = std::sqrt(random.uniform(rMin * rMin, rMax * rMax));  // uniform in the ring
      at = {r * std::cos(angle), r * std::sin(angle)};
      if (groundAt(at.x, at.y).slope < maxSlope) return true;
    }
    return false;
  };

  for (int t = 0; t < kTrees; ++t) {
    glm::dvec2 at;
    if (!placeOnGentleGround(60.0, 1200.0, 0.25, at)) continue;
    const double base = lowestUnder(at.x, at.y, 0.3) - 0.5;
    const double trunk = random.uniform(2.5, 4.0) + 0.5, crown = random.uniform(4.0, 7.0);
    const double width = random.uniform(3.0, 5.0), yaw = random.uniform(0.0, std::numbers::pi);
    PolygonObject tree = makeObject(fmt::format("tree_{:04d}", t + 1), TerrainMaterial::kFoliage);
    addUprightBox(tree, {at.x, base, at.y}, {0.4, trunk, 0.4}, yaw);
    addUprightBox(tree, {at.x, base + trunk, at.y}, {width, crown, width}, yaw);
    scene.objects.push_back(std::move(tree));
  }
  for (int r = 0; r < kRocks; ++r) {
    glm::dvec2 at;
    if (!placeOnGentleGround(100.0, 1700.0, 0.6, at)) continue;
    const glm::dvec3 size(random.uniform(1.0, 4.0), random.uniform(0.8, 2.5),
                          random.uniform(1.0, 4.0));
    const double sunk = 0.3 * size.y;
    const double base =
        lowestUnder(at.x, at.y, 0.5 * std::max(size.x, size.z) * std::sqrt(2.0)) - sunk;
    PolygonObject rock = makeObject(fmt::format("rock_{:03d}", r + 1), TerrainMaterial::kStone);
    addUprightBox(rock, {at.x, base, at.y}, size + glm::dvec3(0.0, sunk, 0.0),
                  random.uniform(0.0, std::numbers::pi));
    scene.objects.push_back(std::move(rock));
  }
  return scene;
}

}  // namespace vistream
