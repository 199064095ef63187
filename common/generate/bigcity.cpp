// A large city with detailed facades, after the test scene of Wimmer,
// "Representing and Rendering Distant Objects for Real-Time Visualization"
// (PhD thesis, TU Wien 2001), Section 5 (results): "Our test scene is 4 square
// kilometers large and consists of 2.1 million polygons", a city whose
// buildings have "not more than a few hundred triangles" each (Section 1.1)
// and whose streets form the view cells (street segments, Figure 5.12).
//
// The thesis shows the city only in figures, so the layout is ours:
//  - 2 km x 2 km centred on the origin, ground at y = 0, Y up, metres.
//  - 18 x 18 blocks of 80-120 m between streets: 20 m avenues every sixth
//    street (and around the border), 11-15 m streets otherwise. Six blocks,
//    away from the border and from each other, are open squares with a
//    monument in the middle.
//  - Perimeter blocks: buildings of 14-20 m depth line the four sides of each
//    block, 1 m behind the block edge, 1.5 m apart, around an open courtyard.
//    Streets and courtyards are free of geometry above the ground.
//  - 3-6 floors in the outskirts, 5-9 within 700 m of the centre and 8-16
//    (sometimes towers of 18-28) within 350 m.
//  - Facades facing a street carry the detail: a protruding window frame per
//    bay and floor (half the buildings with sills below), shop windows on the
//    ground floor, a band at every floor line and a cornice. Back and side
//    walls are plain. Bay widths (3.6-4.8 m), the share of buildings with
//    sills (20%) and the detail set were tuned on seed 1 to give about 2.6
//    million triangles (about 610 per building) over about 4,200 buildings,
//    so that any seed stays above 2 million.
//  - Every piece is a closed box; details are boxes attached to the wall
//    (their back face lies on the wall plane, facing in).
//
// Object order: "streets" (asphalt quads: segments and crossings, no overlap),
// "block_ground" (one quad per block), then per building "building_NNNN"
// (body, bands, cornice and roof housing) directly followed by "windows_NNNN"
// (window frames, sills and shop windows, in glass), then "monument_NN" per
// square. Buildings are numbered from 1 in block order (row-major from -Z,
// -X), and within a block south, north, west and east side.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "common/generate/generate.h"
#include "common/generate/polygon_builder.h"
#include "common/generate/random.h"

namespace vistream {
namespace {

using namespace generate_detail;  // NOLINT(google-build-using-namespace)

constexpr double kExtent = 2000.0;  // metres, the city is kExtent x kExtent
constexpr int kBlocksPerSide = 18;
constexpr int kSquares = 6;
constexpr double kAvenueWidth = 20.0;
constexpr double kSetback = 1.0;      // body behind the block edge; details stay in the block
constexpr double kBuildingGap = 1.5;  // between neighbouring buildings
constexpr double kGroundFloor = 4.2;  // metres, shop floor
constexpr double kUpperFloor = 3.2;   // metres, upper floors

// Material indices, scoped so that no other generator's names meet them.
struct BigCityMaterial {
  enum : uint32_t { kAsphalt, kPavement, kGlass, kStone, kFirstFacade };
};

std::vector<Material> bigCityMaterials() {
  const auto material = &Material::diffuseColour;
  std::vector<Material> materials{
      material("asphalt", {0.20f, 0.20f, 0.21f}), material("pavement", {0.45f, 0.44f, 0.41f}),
      material("glass", {0.16f, 0.22f, 0.30f}), material("stone", {0.62f, 0.60f, 0.55f})};
  const auto facades = facadeMaterials();
  materials.insert(materials.end(), facades.begin(), facades.end());
  return materials;
}

struct Interval {
  double lo, hi;
  double size() const { return hi - lo; }
};

// Streets and blocks along one axis: streets[k] lies before blocks[k], and
// streets[kBlocksPerSide] closes the city.
struct StreetGrid {
  std::vector<Interval> streets;
  std::vector<Interval> blocks;
};

StreetGrid makeStreetGrid(SceneRandom& random) {
  std::vector<double> streetWidth(kBlocksPerSide + 1);
  for (int k = 0; k <= kBlocksPerSide; ++k)
    streetWidth[size_t(k)] = k % 6 == 0 ? kAvenueWidth : random.uniform(11.0, 15.0);
  std::vector<double> weight(kBlocksPerSide);
  for (double& w : weight) w = random.uniform(0.8, 1.2);
  double streets = 0.0, weights = 0.0;
  for (double w : streetWidth) streets += w;
  for (double w : weight) weights += w;
  const double scale = (kExtent - streets) / weights;

  StreetGrid grid;
  double p = -0.5 * kExtent;
  for (int k = 0; k <= kBlocksPerSide; ++k) {
    grid.streets.push_back({p, p + streetWidth[size_t(k)]});
    p += streetWidth[size_t(k)];
    if (k < kBlocksPerSide) {
      grid.blocks.push_back({p, p + weight[size_t(k)] * scale});
      p += weight[size_t(k)] * scale;
    }
  }
  grid.streets.back().hi = 0.5 * kExtent;  // absorb rounding
  return grid;
}

// A wall of a building seen from outside: points are origin + u * along +
// y * up + o * outward, for u in [0, width].
struct Facade {
  glm::dvec3 origin;
  glm::dvec3 along;
  glm::dvec3 outward;
  double width;
};

// Closed box attached to a facade, from u0 to u1 along it, y0 to y1 up and
// protruding `depth` out of the wall.
void addFacadeBox(PolygonObject& object, const Facade& facade, double u0, double u1, double y0,
                  double y1, double depth) {
  const glm::dvec3 up(0.0, 1.0, 0.0);
  addBox(object, facade.origin + u0 * facade.along + y0 * up,
         facade.origin + u1 * facade.along + y1 * up + depth * facade.outward);
}

struct BuildingStyle {
  int floors;
  double bayWidth;
  bool sills;
};

// Windows, sills, shop windows, floor bands and cornice of one street facade.
void decorateFacade(PolygonObject& body, PolygonObject& windows, const Facade& facade,
                    const BuildingStyle& style, double height) {
  const int bays = std::max(1, int(facade.width / style.bayWidth));
  const double margin = 0.5 * (facade.width - bays * style.bayWidth);
  const double windowWidth = 0.5 * style.bayWidth;
  for (int b = 0; b < bays; ++b) {
    const double centre = margin + (b + 0.5) * style.bayWidth;
    // Shop window: wide and low on the ground floor.
    const double shop = 0.35 * style.bayWidth;
    addFacadeBox(windows, facade, centre - shop, centre + shop, 0.4, 3.0, 0.1);
    for (int f = 1; f < style.floors; ++f) {
      const double floorBase = kGroundFloor + (f - 1) * kUpperFloor;
      const double u0 = centre - 0.5 * windowWidth, u1 = centre + 0.5 * windowWidth;
      addFacadeBox(windows, facade, u0, u1, floorBase + 0.9, floorBase + 2.4, 0.12);
      if (style.sills)
        addFacadeBox(windows, facade, u0 - 0.15, u1 + 0.15, floorBase + 0.78, floorBase + 0.9, 0.3);
    }
  }
  // Bands at the floor lines (between the windows), cornice at the roof line.
  for (int f = 1; f < style.floors; ++f) {
    const double line = kGroundFloor + (f - 1) * kUpperFloor;
    addFacadeBox(body, facade, 0.0, facade.width, line - 0.1, line + 0.15, 0.2);
  }
  addFacadeBox(body, facade, 0.0, facade.width, height - 0.7, height, 0.5);
}

// One building on footprint [lo, hi] (x, z), its street facades listed by
// outward direction.
void addBuilding(PolygonScene& scene, SceneRandom& random, int number, glm::dvec2 lo, glm::dvec2 hi,
                 const std::vector<glm::dvec3>& streetSides) {
  const glm::dvec2 centre = 0.5 * (lo + hi);
  const double r = glm::length(centre);
  BuildingStyle style{};
  if (r < 350.0) {
    style.floors = random.chance(0.15) ? random.integer(18, 28) : random.integer(8, 16);
  } else if (r < 700.0) {
    style.floors = random.integer(5, 9);
  } else {
    style.floors = random.integer(3, 6);
  }
  style.bayWidth = random.uniform(3.6, 4.8);
  style.sills = random.chance(0.2);
  const double height = kGroundFloor + (style.floors - 1) * kUpperFloor;

  PolygonObject body =
      makeObject(fmt::format("building_{:04d}", number),
                 BigCityMaterial::kFirstFacade + uint32_t(random.below(kFacadeMaterials)));
  PolygonObject windows =
      makeObject(fmt::format("windows_{:04d}", number), BigCityMaterial::kGlass);
  addBox(body, {lo.x, 0.0, lo.y}, {hi.x, height, hi.y});

  for (const glm::dvec3& side : streetSides) {
    Facade facade{};
    facade.outward = side;
    if (side.z != 0.0) {
      facade.origin = {lo.x, 0.0, side.z < 0.0 ? lo.y : hi.y};
      facade.along = {1.0, 0.0, 0.0};
      facade.width = hi.x - lo.x;
    } else {
      facade.origin = {side.x < 0.0 ? lo.x : hi.x, 0.0, lo.y};
      facade.along = {0.0, 0.0, 1.0};
      facade.width = hi.y - lo.y;
    }
    decorateFacade(body, windows, facade, style, height);
  }

  // Roof housing (stairs, lift machinery) on most roofs.
  const glm::dvec2 size = hi - lo;
  if (random.chance(0.6) && size.x > 10.0 && size.y > 10.0) {
    const glm::dvec2 housing(random.uniform(3.0, 6.0), random.uniform(3.0, 6.0));
    const glm::dvec2 at(random.uniform(lo.x + 1.5, hi.x - 1.5 - housing.x),
                        random.uniform(lo.y + 1.5, hi.y - 1.5 - housing.y));
    addBox(body, {at.x, height, at.y},
           {at.x + housing.x, height + random.uniform(2.5, 3.5), at.y + housing.y});
  }
  scene.objects.push_back(std::move(body));
  scene.objects.push_back(std::move(windows));
}

// Splits [lo, hi] into parcels of about `typical` metres with gaps between.
std::vector<Interval> splitIntoParcels(SceneRandom& random, Interval span, double typical) {
  const int n = std::max(1, int(std::lround(span.size() / typical)));
  std::vector<double> weight(static_cast<size_t>(n));
  double total = 0.0;
  for (double& w : weight) total += (w = random.uniform(0.7, 1.3));
  const double usable = span.size() - (n - 1) * kBuildingGap;
  std::vector<Interval> parcels;
  double p = span.lo;
  for (int i = 0; i < n; ++i) {
    const double w = weight[size_t(i)] / total * usable;
    parcels.push_back({p, i + 1 == n ? span.hi : p + w});
    p += w + kBuildingGap;
  }
  return parcels;
}

}  // namespace

PolygonScene generateBigCity(uint64_t seed) {
  SceneRandom random(seed);
  PolygonScene scene;
  scene.name = "bigcity";
  scene.materials = bigCityMaterials();

  const StreetGrid gx = makeStreetGrid(random), gz = makeStreetGrid(random);

  // Open squares: interior blocks, no two touching.
  std::vector<glm::ivec2> squares;
  while (int(squares.size()) < kSquares) {
    const glm::ivec2 b(random.integer(2, kBlocksPerSide - 3),
                       random.integer(2, kBlocksPerSide - 3));
    bool free = true;
    for (const glm::ivec2& s : squares)
      free = free && std::max(std::abs(s.x - b.x), std::abs(s.y - b.y)) > 1;
    if (free) squares.push_back(b);
  }
  auto isSquare = [&](int bx, int bz) {
    return std::any_of(squares.begin(), squares.end(),
                       [&](const glm::ivec2& s) { return s.x == bx && s.y == bz; });
  };

  // Ground: street segments and crossings, then one quad per block; all face up.
  auto groundQuad = [](PolygonObject& o, Interval x, Interval z) {
    addQuad(o, {x.lo, 0.0, z.lo}, {x.lo, 0.0, z.hi}, {x.hi, 0.0, z.hi}, {x.hi, 0.0, z.lo});
  };
  PolygonObject streets = makeObject("streets", BigCityMaterial::kAsphalt);
  for (int i = 0; i <= kBlocksPerSide; ++i) {
    for (int j = 0; j <= kBlocksPerSide; ++j) {
      groundQuad(streets, gx.streets[size_t(i)], gz.streets[size_t(j)]);  // crossing
      if (j < kBlocksPerSide) groundQuad(streets, gx.streets[size_t(i)], gz.blocks[size_t(j)]);
      if (i < kBlocksPerSide) groundQuad(streets, gx.blocks[size_t(i)], gz.streets[size_t(j)]);
    }
  }
  PolygonObject blockGround = makeObject("block_ground", BigCityMaterial::kPavement);
  for (int j = 0; j < kBlocksPerSide; ++j)
    for (int i = 0; i < kBlocksPerSide; ++i)
      groundQuad(blockGround, gx.blocks[size_t(i)], gz.blocks[size_t(j)]);
  scene.objects.push_back(std::move(streets));
  scene.objects.push_back(std::move(blockGround));

  int number = 0;
  const glm::dvec3 south(0, 0, -1), north(0, 0, 1), west(-1, 0, 0), east(1, 0, 0);
  for (int j = 0; j < kBlocksPerSide; ++j) {
    for (int i = 0; i < kBlocksPerSide; ++i) {
      if (isSquare(i, j)) continue;
      const Interval bx{gx.blocks[size_t(i)].lo + kSetback, gx.blocks[size_t(i)].hi - kSetback};
      const Interval bz{gz.blocks[size_t(j)].lo + kSetback, gz.blocks[size_t(j)].hi - kSetback};
      const double depthSouth = random.uniform(14.0, 20.0), depthNorth = random.uniform(14.0, 20.0);
      const double depthWest = random.uniform(14.0, 20.0), depthEast = random.uniform(14.0, 20.0);

      // South and north rows span the whole block; their end buildings are corners.
      for (const bool isNorth : {false, true}) {
        const std::vector<Interval> parcels = splitIntoParcels(random, bx, 23.0);
        for (size_t p = 0; p < parcels.size(); ++p) {
          std::vector<glm::dvec3> sides{isNorth ? north : south};
          if (p == 0) sides.push_back(west);
          if (p + 1 == parcels.size()) sides.push_back(east);
          const double z0 = isNorth ? bz.hi - depthNorth : bz.lo;
          const double z1 = isNorth ? bz.hi : bz.lo + depthSouth;
          addBuilding(scene, random, ++number, {parcels[p].lo, z0}, {parcels[p].hi, z1}, sides);
        }
      }
      // West and east columns fill the rest of the sides.
      const Interval between{bz.lo + depthSouth + kBuildingGap, bz.hi - depthNorth - kBuildingGap};
      if (between.size() < 10.0) continue;
      for (const bool isEast : {false, true}) {
        const std::vector<Interval> parcels = splitIntoParcels(random, between, 23.0);
        for (const Interval& parcel : parcels) {
          const double x0 = isEast ? bx.hi - depthEast : bx.lo;
          const double x1 = isEast ? bx.hi : bx.lo + depthWest;
          addBuilding(scene, random, ++number, {x0, parcel.lo}, {x1, parcel.hi},
                      {isEast ? east : west});
        }
      }
    }
  }

  // A monument (pedestal and column) in the middle of each square.
  for (size_t s = 0; s < squares.size(); ++s) {
    const Interval x = gx.blocks[size_t(squares[s].x)], z = gz.blocks[size_t(squares[s].y)];
    const glm::dvec2 c(0.5 * (x.lo + x.hi), 0.5 * (z.lo + z.hi));
    PolygonObject monument =
        makeObject(fmt::format("monument_{:02d}", s + 1), BigCityMaterial::kStone);
    addBox(monument, {c.x - 4.0, 0.0, c.y - 4.0}, {c.x + 4.0, 1.5, c.y + 4.0});
    addBox(monument, {c.x - 1.0, 1.5, c.y - 1.0},
           {c.x + 1.0, random.uniform(10.0, 18.0), c.y + 1.0});
    scene.objects.push_back(std::move(monument));
  }
  return scene;
}

}  // namespace vistream
