// The test cities of Cohen-Or and Zadicario, "Visibility Streaming for
// Network-based Walkthroughs" (1998), Section 5 (Results) and Table 1:
// "city1" has 21,280 polygons forming 2,128 buildings "of two types. Most
// buildings are simple boxes and about 25% are made of three boxes of random
// height placed one above the another"; "city2" has the same polygon count
// with a sparser distribution of buildings.
//
// The paper gives no lot size, street width or heights (its Figure 2 is lost
// in our transcription); what we chose, and why:
//  - Buildings stand on a regular 56 x 38 lot grid (56 * 38 = 2,128) with
//    streets between the lots, so walkthrough paths can follow the streets.
//  - Exactly 25% (532) of the buildings are three stacked boxes. With closed
//    boxes of 6 quads and one ground quad per lot this gives
//    1,596 * 6 + 532 * 18 + 2,128 = 21,280 polygons: the paper's count.
//  - Every box is closed (the paper's occluders are convex closed objects);
//    a building is one object, its boxes in order from the ground up.
//  - Dense city: 24 m lots, 8 m streets, footprints filling 70-100% of the lot
//    side (about 41% of the ground built up). Sparse city: 38 m lots, 10 m
//    streets, 14-22 m footprints placed anywhere in the lot (about 14%).
//  - Heights 8-40 m for simple boxes, 4-14 m per stacked box, each upper box
//    inset by 10-20% of the lower one's side on each side.
//
// Layout: Y up, metres, the city centred on the origin with the ground at
// y = 0. Object order: "ground" (one quad per lot, row-major from -Z, -X,
// each tile the whole lot cell including half of the streets around it), then
// "building_0001" .. "building_2128" in the same lot order. Streets run along
// x and z between the lot rows and columns and are free of geometry above the
// ground.
#include <fmt/format.h>

#include <algorithm>
#include <utility>
#include <vector>

#include "common/generate/generate.h"
#include "common/generate/polygon_builder.h"
#include "common/generate/random.h"

namespace vistream {
namespace {

using namespace generate_detail;  // NOLINT(google-build-using-namespace)

constexpr int kLotColumns = 56;  // along x
constexpr int kLotRows = 38;     // along z
constexpr int kBuildings = kLotColumns * kLotRows;
constexpr int kStackedBuildings = kBuildings / 4;  // "about 25%": exactly 532

struct CityLayout {
  double lot;           // side of a building lot, metres
  double street;        // street width between lots, metres
  double minFootprint;  // building side range, metres
  double maxFootprint;
};

// Dense: buildings nearly fill their lots along narrow streets.
constexpr CityLayout kDense{24.0, 8.0, 0.7 * 24.0, 24.0};
// Sparse: the same buildings, smaller, scattered over wider lots.
constexpr CityLayout kSparse{38.0, 10.0, 14.0, 22.0};

// Material indices, scoped so that no other generator's names meet them.
struct CityMaterial {
  enum : uint32_t { kGround, kFirstFacade };
};

std::vector<Material> cityMaterials() {
  const auto material = &Material::diffuseColour;
  std::vector<Material> materials{material("ground", {0.32f, 0.34f, 0.30f})};
  const auto facades = facadeMaterials();
  materials.insert(materials.end(), facades.begin(), facades.end());
  return materials;
}

}  // namespace

PolygonScene generateCity(bool dense, uint64_t seed) {
  const CityLayout& layout = dense ? kDense : kSparse;
  SceneRandom random(seed);

  PolygonScene scene;
  scene.name = dense ? "city1" : "city2";
  scene.materials = cityMaterials();

  // Which buildings are the stacked type: exactly a quarter, scattered.
  std::vector<uint8_t> stacked(kBuildings, 0);
  std::fill(stacked.begin(), stacked.begin() + kStackedBuildings, 1);
  random.shuffle(stacked);

  const double pitch = layout.lot + layout.street;
  const double x0 = -0.5 * kLotColumns * pitch, z0 = -0.5 * kLotRows * pitch;

  PolygonObject ground = makeObject("ground", CityMaterial::kGround);
  ground.vertices.reserve(4 * kBuildings);
  ground.faces.reserve(kBuildings);
  scene.objects.reserve(kBuildings + 1);
  std::vector<PolygonObject> buildings;
  buildings.reserve(kBuildings);

  for (int row = 0; row < kLotRows; ++row) {
    for (int column = 0; column < kLotColumns; ++column) {
      const int index = row * kLotColumns + column;
      const double cellX = x0 + column * pitch, cellZ = z0 + row * pitch;
      // Ground tile over the whole cell, wound to face up; neighbours share
      // edges exactly (same expression), so the ground has no cracks.
      const double nextX = x0 + (column + 1) * pitch, nextZ = z0 + (row + 1) * pitch;
      addQuad(ground, {cellX, 0.0, cellZ}, {cellX, 0.0, nextZ}, {nextX, 0.0, nextZ},
              {nextX, 0.0, cellZ});

      // Footprint somewhere inside the lot (the cell minus half a street on each side).
      const double lotX = cellX + 0.5 * layout.street, lotZ = cellZ + 0.5 * layout.street;
      const double width = random.uniform(layout.minFootprint, layout.maxFootprint);
      const double depth = random.uniform(layout.minFootprint, layout.maxFootprint);
      glm::dvec2 lo{lotX + random.uniform(0.0, layout.lot - width),
                    lotZ + random.uniform(0.0, layout.lot - depth)};
      glm::dvec2 hi = lo + glm::dvec2(width, depth);

      PolygonObject building =
          makeObject(fmt::format("building_{:04d}", index + 1),
                     CityMaterial::kFirstFacade + uint32_t(random.below(kFacadeMaterials)));
      if (!stacked[size_t(index)]) {
        addBox(building, {lo.x, 0.0, lo.y}, {hi.x, random.uniform(8.0, 40.0), hi.y});
      } else {
        double base = 0.0;
        for (int level = 0; level < 3; ++level) {
          if (level > 0) {
            // Each upper box is inset on every side, so no two boxes share a face.
            const glm::dvec2 size = hi - lo;
            lo += glm::dvec2(random.uniform(0.1, 0.2) * size.x, random.uniform(0.1, 0.2) * size.y);
            hi -= glm::dvec2(random.uniform(0.1, 0.2) * size.x, random.uniform(0.1, 0.2) * size.y);
          }
          const double top = base + random.uniform(4.0, 14.0);
          addBox(building, {lo.x, base, lo.y}, {hi.x, top, hi.y});
          base = top;
        }
      }
      buildings.push_back(std::move(building));
    }
  }

  scene.objects.push_back(std::move(ground));
  for (PolygonObject& b : buildings) scene.objects.push_back(std::move(b));
  return scene;
}

}  // namespace vistream
