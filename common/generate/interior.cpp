// One building floor of rooms, corridors and doors with furniture, sized like
// scene I of Bittner and Havran, "Exploiting coherence in hierarchical
// visibility algorithms" (J. Visual. Comput. Animat. 2001), Section "Results
// and Discussion": the fifth floor of Soda Hall, whose kD-tree "consisted of
// 1187 nodes". The Soda Hall model itself is not ours to ship, so this floor
// only matches its kind and size: about 40 m x 40 m, two long corridors joined
// by a cross corridor, 26 offices with a door each, and about 440 objects
// (walls, lintels, tables, desks, chairs, shelves; about 13,000 faces). The
// amount of furniture was tuned so that the kD-tree over the objects
// (KdTree::buildOverObjects, default options) has 1,120-1,160 nodes on seeds
// 1-6, against the paper's 1,187.
//
// Plan (x to the east, z to the north, Y up, metres, floor at y = 0):
//
//   z = +20  +-----------------------------------------+
//            |  north offices (7, 11 m deep)            |
//   z = +9   +---d-------d------d------d-----d-----d----+
//            |  north corridor (2 m)                    |
//   z = +7   +--d----d------d--+  +--d------d-----d-----+
//            |  offices (7 m)  |  |   offices          |
//   z = 0    +-----------------+  +--------------------+   cross corridor
//            |  offices (7 m)  |  |   offices          |   x in [-1, 1]
//   z = -7   +--d----d------d--+  +--d------d-----d-----+
//            |  south corridor (2 m)                    |
//   z = -9   +---d-------d------d------d-----d-----d----+
//            |  south offices (7, 11 m deep)            |
//   z = -20  +-----------------------------------------+
//
// Walls are closed boxes 0.2 m thick and 3 m high centred on the lines above;
// no two wall boxes overlap (walls running along z stop at the faces of walls
// running along x). Each office has one door: a 1 m gap in its corridor wall
// with a lintel box from 2.1 m to the 3 m ceiling. Furniture (tables with
// chairs in the room, desks with a chair and shelves flush against the walls)
// keeps a clear zone behind each door.
// Floor and ceiling are 2 m tiles (floor facing up, ceiling facing down), so
// visibility can cull them piecewise.
//
// Object order: "floor", "ceiling", then walls and lintels line by line
// ("wall_NNN", "lintel_NNN"), then furniture room by room ("table_NNN",
// "chair_NNN", "desk_NNN", "shelf_NNN").
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <utility>
#include <vector>

#include "common/generate/generate.h"
#include "common/generate/polygon_builder.h"
#include "common/generate/random.h"

namespace vistream {
namespace {

using namespace generate_detail;  // NOLINT(google-build-using-namespace)

constexpr double kHalfSize = 20.0;  // outer wall centre lines at +-20 m
constexpr double kHalfWall = 0.1;   // walls are 0.2 m thick
constexpr double kStorey = 3.0;     // floor to ceiling
constexpr double kDoorWidth = 1.0;
constexpr double kDoorHeight = 2.1;
constexpr double kCrossCorridor = 1.0;  // cross corridor wall centre lines at +-1 m
constexpr int kTilesPerSide = 20;

// Material indices, scoped so that no other generator's names meet them.
struct InteriorMaterial {
  enum : uint32_t { kFloor, kCeiling, kWall, kWood, kFabric, kShelf };
};

std::vector<Material> interiorMaterials() {
  const auto material = &Material::diffuseColour;
  return {material("floor", {0.50f, 0.46f, 0.40f}),  material("ceiling", {0.90f, 0.90f, 0.88f}),
          material("wall", {0.82f, 0.80f, 0.74f}),   material("wood", {0.55f, 0.38f, 0.22f}),
          material("fabric", {0.22f, 0.30f, 0.45f}), material("shelf", {0.42f, 0.30f, 0.20f})};
}

struct Rect {  // in the floor plane: x and z
  double x0, x1, z0, z1;
  bool overlaps(const Rect& o) const { return x0 < o.x1 && o.x0 < x1 && z0 < o.z1 && o.z0 < z1; }
  bool inside(const Rect& o) const { return x0 >= o.x0 && x1 <= o.x1 && z0 >= o.z0 && z1 <= o.z1; }
};

struct Office {
  Rect inside;        // between the wall faces
  double doorCentre;  // x of the door
  bool doorAtLowZ;    // the door is in the wall at inside.z0 (else at inside.z1)
};

class FloorBuilder {
 public:
  FloorBuilder(PolygonScene& scene, SceneRandom& random, double wallPatch)
      : scene_(scene), random_(random), wallPatch_(wallPatch) {}

  // A wall running along x at line z, its box from x0 to x1, with doors
  // (gaps with lintels) centred at doorCentres.
  void wallAlongX(double z, double x0, double x1, std::vector<double> doorCentres) {
    std::sort(doorCentres.begin(), doorCentres.end());
    double from = x0;
    for (double c : doorCentres) {
      const double gap0 = c - 0.5 * kDoorWidth, gap1 = c + 0.5 * kDoorWidth;
      wallBox({from, 0.0, z - kHalfWall}, {gap0, kStorey, z + kHalfWall});
      PolygonObject lintel =
          makeObject(fmt::format("lintel_{:03d}", ++lintels_), InteriorMaterial::kWall);
      addBox(lintel, {gap0, kDoorHeight, z - kHalfWall}, {gap1, kStorey, z + kHalfWall});
      scene_.objects.push_back(std::move(lintel));
      from = gap1;
    }
    wallBox({from, 0.0, z - kHalfWall}, {x1, kStorey, z + kHalfWall});
  }

  // A wall running along z at line x, its box from z0 to z1, without doors.
  void wallAlongZ(double x, double z0, double z1) {
    wallBox({x - kHalfWall, 0.0, z0}, {x + kHalfWall, kStorey, z1});
  }

  void furnish(const Office& office) {
    const Rect& r = office.inside;
    // Nothing stands in the 1.8 m x 1.5 m zone behind the door.
    std::vector<Rect> taken;
    const double doorZ = office.doorAtLowZ ? r.z0 : r.z1;
    taken.push_back({office.doorCentre - 0.9, office.doorCentre + 0.9,
                     office.doorAtLowZ ? doorZ : doorZ - 1.5,
                     office.doorAtLowZ ? doorZ + 1.5 : doorZ});

    const double area = (r.x1 - r.x0) * (r.z1 - r.z0);
    const int tables = area > 45.0 ? 2 : 1;
    for (int t = 0; t < tables; ++t) placeTableWithChairs(r, taken);
    const int desks = random_.integer(2, 3);
    for (int d = 0; d < desks; ++d) placeDeskWithChair(r, taken);
    const int shelves = random_.integer(1, 3);
    for (int s = 0; s < shelves; ++s) placeShelf(r, taken);
  }

 private:
  // A wall box, or with wallPatch_ set, a row of boxes at most that long
  // (the patches of a radiosity solution), each its own object.
  void wallBox(const glm::dvec3& lo, const glm::dvec3& hi) {
    if (hi.x - lo.x < 1e-6 || hi.z - lo.z < 1e-6) return;  // a door flush with a wall end
    const int axis = hi.x - lo.x >= hi.z - lo.z ? 0 : 2;
    const int pieces = wallPatch_ > 0.0
                           ? std::max(1, int(std::ceil((hi[axis] - lo[axis]) / wallPatch_ - 1e-9)))
                           : 1;
    for (int k = 0; k < pieces; ++k) {
      glm::dvec3 a = lo, b = hi;
      // Shared ends come from the same expression: no cracks between patches.
      a[axis] = k == 0 ? lo[axis] : lo[axis] + (hi[axis] - lo[axis]) * k / pieces;
      b[axis] = k + 1 == pieces ? hi[axis] : lo[axis] + (hi[axis] - lo[axis]) * (k + 1) / pieces;
      PolygonObject wall =
          makeObject(fmt::format("wall_{:03d}", ++walls_), InteriorMaterial::kWall);
      addBox(wall, a, b);
      scene_.objects.push_back(std::move(wall));
    }
  }

  // A 1.6 m x 0.8 m table with one or two chairs on each long side; the table
  // and the space its chairs need must fit 0.3 m clear of the walls.
  void placeTableWithChairs(const Rect& room, std::vector<Rect>& taken) {
    const bool alongX = random_.chance(0.5);
    const double halfLong = 0.8, halfShort = 0.4, chairReach = 0.75;
    const double hx = alongX ? halfLong : halfShort + chairReach;
    const double hz = alongX ? halfShort + chairReach : halfLong;
    for (int attempt = 0; attempt < 40; ++attempt) {
      const double margin = 0.3;
      if (room.x1 - room.x0 < 2 * (hx + margin) || room.z1 - room.z0 < 2 * (hz + margin)) return;
      const double cx = random_.uniform(room.x0 + hx + margin, room.x1 - hx - margin);
      const double cz = random_.uniform(room.z0 + hz + margin, room.z1 - hz - margin);
      const Rect footprint{cx - hx, cx + hx, cz - hz, cz + hz};
      if (std::any_of(taken.begin(), taken.end(),
                      [&](const Rect& o) { return o.overlaps(footprint); }))
        continue;
      taken.push_back(footprint);

      const double tx = alongX ? halfLong : halfShort, tz = alongX ? halfShort : halfLong;
      PolygonObject table =
          makeObject(fmt::format("table_{:03d}", ++tables_), InteriorMaterial::kWood);
      addBox(table, {cx - tx, 0.71, cz - tz}, {cx + tx, 0.75, cz + tz});
      for (const double sx : {-1.0, 1.0})
        for (const double sz : {-1.0, 1.0}) {
          const double lx = cx + sx * (tx - 0.08), lz = cz + sz * (tz - 0.08);
          addBox(table, {lx - 0.03, 0.0, lz - 0.03}, {lx + 0.03, 0.71, lz + 0.03});
        }
      scene_.objects.push_back(std::move(table));

      // Chairs face the table from both long sides.
      for (const double side : {-1.0, 1.0}) {
        const int count = random_.integer(1, 2);
        for (int k = 0; k < count; ++k) {
          const double offset = count == 1 ? 0.0 : (k == 0 ? -0.4 : 0.4);
          const double distance = halfShort + 0.35;  // table edge to seat centre
          const glm::dvec2 seat = alongX ? glm::dvec2(cx + offset, cz + side * distance)
                                         : glm::dvec2(cx + side * distance, cz + offset);
          addChair(seat, alongX ? glm::dvec2(0.0, side) : glm::dvec2(side, 0.0));
        }
      }
      return;
    }
  }

  // Seat, four legs and a back on the side `away` from the table.
  void addChair(const glm::dvec2& seat, const glm::dvec2& away) {
    PolygonObject chair =
        makeObject(fmt::format("chair_{:03d}", ++chairs_), InteriorMaterial::kFabric);
    const double h = 0.22;  // half seat
    addBox(chair, {seat.x - h, 0.43, seat.y - h}, {seat.x + h, 0.47, seat.y + h});
    for (const double sx : {-1.0, 1.0})
      for (const double sz : {-1.0, 1.0}) {
        const double lx = seat.x + sx * (h - 0.03), lz = seat.y + sz * (h - 0.03);
        addBox(chair, {lx - 0.02, 0.0, lz - 0.02}, {lx + 0.02, 0.43, lz + 0.02});
      }
    const glm::dvec2 backCentre = seat + away * (h - 0.02);
    const glm::dvec2 half = away.x != 0.0 ? glm::dvec2(0.02, h) : glm::dvec2(h, 0.02);
    addBox(chair, {backCentre.x - half.x, 0.47, backCentre.y - half.y},
           {backCentre.x + half.x, 0.95, backCentre.y + half.y});
    scene_.objects.push_back(std::move(chair));
  }

  // A place flush against one of the room's walls, `width` along it and
  // `depth` into the room, with `clearance` more in front kept free (for a
  // chair); 1 cm clear of the walls at its ends.
  struct WallSpot {
    Rect footprint;  // the piece itself
    int wall;        // -X, +X, -Z, +Z side of the room
    double u0;       // where the piece starts along the wall
    double wallCoordinate;

    bool alongX() const { return wall >= 2; }
    // Direction from the wall into the room, in (x, z).
    glm::dvec2 intoRoom() const {
      const double sign = (wall == 0 || wall == 2) ? 1.0 : -1.0;
      return alongX() ? glm::dvec2(0.0, sign) : glm::dvec2(sign, 0.0);
    }
    // Local frame: u along the wall, v from the wall into the room.
    glm::dvec3 at(double u, double y, double v) const {
      const glm::dvec2 into = intoRoom();
      const double w = wallCoordinate + v * (alongX() ? into.y : into.x);
      return alongX() ? glm::dvec3(u0 + u, y, w) : glm::dvec3(w, y, u0 + u);
    }
  };

  std::optional<WallSpot> findWallSpot(const Rect& room, std::vector<Rect>& taken, double width,
                                       double depth, double clearance) {
    for (int attempt = 0; attempt < 40; ++attempt) {
      WallSpot spot{};
      spot.wall = random_.integer(0, 3);
      const double span0 = spot.alongX() ? room.x0 : room.z0;
      const double span1 = spot.alongX() ? room.x1 : room.z1;
      if (span1 - span0 < width + 0.02) continue;
      spot.u0 = random_.uniform(span0 + 0.01, span1 - width - 0.01);
      const double u1 = spot.u0 + width;
      // Flush (exactly) with the wall: the wall side takes the room's own coordinate.
      Rect reserved{};
      switch (spot.wall) {
        case 0:
          spot.wallCoordinate = room.x0;
          spot.footprint = {room.x0, room.x0 + depth, spot.u0, u1};
          reserved = {room.x0, room.x0 + depth + clearance, spot.u0, u1};
          break;
        case 1:
          spot.wallCoordinate = room.x1;
          spot.footprint = {room.x1 - depth, room.x1, spot.u0, u1};
          reserved = {room.x1 - depth - clearance, room.x1, spot.u0, u1};
          break;
        case 2:
          spot.wallCoordinate = room.z0;
          spot.footprint = {spot.u0, u1, room.z0, room.z0 + depth};
          reserved = {spot.u0, u1, room.z0, room.z0 + depth + clearance};
          break;
        default:
          spot.wallCoordinate = room.z1;
          spot.footprint = {spot.u0, u1, room.z1 - depth, room.z1};
          reserved = {spot.u0, u1, room.z1 - depth - clearance, room.z1};
          break;
      }
      if (std::any_of(taken.begin(), taken.end(),
                      [&](const Rect& o) { return o.overlaps(reserved); }))
        continue;
      taken.push_back(reserved);
      return spot;
    }
    return std::nullopt;
  }

  // A shelf against a wall: two sides, a back, bottom, three boards and top.
  void placeShelf(const Rect& room, std::vector<Rect>& taken) {
    const double width = random_.uniform(0.9, 1.8), depth = 0.4;
    const double height = random_.uniform(1.8, 2.1);
    const std::optional<WallSpot> spot = findWallSpot(room, taken, width, depth, 0.0);
    if (!spot) return;
    PolygonObject shelf =
        makeObject(fmt::format("shelf_{:03d}", ++shelves_), InteriorMaterial::kShelf);
    const double side = 0.03, board = 0.03;
    addBox(shelf, spot->at(0.0, 0.0, 0.0), spot->at(side, height, depth));
    addBox(shelf, spot->at(width - side, 0.0, 0.0), spot->at(width, height, depth));
    addBox(shelf, spot->at(side, 0.0, 0.0), spot->at(width - side, height, 0.02));  // back
    for (int b = 0; b < 5; ++b) {
      const double y = b == 4 ? height - board : b * (height - board) / 4.0;
      addBox(shelf, spot->at(side, y, 0.02), spot->at(width - side, y + board, depth));
    }
    scene_.objects.push_back(std::move(shelf));
  }

  // A desk against a wall (top on two side panels) with its chair in front.
  void placeDeskWithChair(const Rect& room, std::vector<Rect>& taken) {
    const double width = random_.uniform(1.2, 1.6), depth = 0.7;
    const std::optional<WallSpot> spot = findWallSpot(room, taken, width, depth, 0.9);
    if (!spot) return;
    PolygonObject desk = makeObject(fmt::format("desk_{:03d}", ++desks_), InteriorMaterial::kWood);
    addBox(desk, spot->at(0.0, 0.72, 0.0), spot->at(width, 0.75, depth));
    addBox(desk, spot->at(0.0, 0.0, 0.0), spot->at(0.03, 0.72, depth));
    addBox(desk, spot->at(width - 0.03, 0.0, 0.0), spot->at(width, 0.72, depth));
    scene_.objects.push_back(std::move(desk));
    const glm::dvec3 seat = spot->at(0.5 * width, 0.0, depth + 0.35);
    addChair({seat.x, seat.z}, spot->intoRoom());
  }

  PolygonScene& scene_;
  SceneRandom& random_;
  double wallPatch_ = 0.0;
  int walls_ = 0, lintels_ = 0, tables_ = 0, desks_ = 0, chairs_ = 0, shelves_ = 0;
};

// Splits [lo, hi] (wall centre lines) into rooms of about 4.5-7 m.
std::vector<double> roomLines(SceneRandom& random, double lo, double hi) {
  const int rooms = std::max(1, int((hi - lo) / 5.6 + 0.5));
  std::vector<double> weight(static_cast<size_t>(rooms));
  double total = 0.0;
  for (double& w : weight) total += (w = random.uniform(0.8, 1.25));
  std::vector<double> lines{lo};
  for (int i = 0; i + 1 < rooms; ++i)
    lines.push_back(lines.back() + weight[size_t(i)] / total * (hi - lo));
  lines.push_back(hi);
  return lines;
}

}  // namespace

PolygonScene generateInterior(uint64_t seed, double wallPatch) {
  SceneRandom random(seed);
  PolygonScene scene;
  scene.name = "interior";
  scene.materials = interiorMaterials();

  // Floor (facing up) and ceiling (facing down) tiles over the outer walls' extent.
  const double outer = kHalfSize + kHalfWall, tile = 2.0 * outer / kTilesPerSide;
  PolygonObject floor = makeObject("floor", InteriorMaterial::kFloor);
  PolygonObject ceiling = makeObject("ceiling", InteriorMaterial::kCeiling);
  for (int j = 0; j < kTilesPerSide; ++j)
    for (int i = 0; i < kTilesPerSide; ++i) {
      // Shared edges come from the same expression: no cracks between tiles.
      const double x0 = -outer + i * tile, x1 = -outer + (i + 1) * tile;
      const double z0 = -outer + j * tile, z1 = -outer + (j + 1) * tile;
      addQuad(floor, {x0, 0.0, z0}, {x0, 0.0, z1}, {x1, 0.0, z1}, {x1, 0.0, z0});
      addQuad(ceiling, {x0, kStorey, z0}, {x1, kStorey, z0}, {x1, kStorey, z1}, {x0, kStorey, z1});
    }
  scene.objects.push_back(std::move(floor));
  scene.objects.push_back(std::move(ceiling));

  // Offices: band (z range of wall lines), x range of wall lines, door side.
  struct Band {
    double z0, z1;
    bool doorAtLowZ;
    bool split;  // interrupted by the cross corridor
  };
  const std::array<Band, 4> bands{{{-kHalfSize, -9.0, false, false},
                                   {-7.0, 0.0, true, true},
                                   {0.0, 7.0, false, true},
                                   {9.0, kHalfSize, true, false}}};
  struct Divider {
    double x;
    const Band* band;
  };
  std::vector<Office> offices;
  std::vector<Divider> dividers;
  for (const Band& band : bands) {
    std::vector<std::pair<double, double>> spans;
    if (band.split) {
      spans = {{-kHalfSize, -kCrossCorridor}, {kCrossCorridor, kHalfSize}};
    } else {
      spans = {{-kHalfSize, kHalfSize}};
    }
    for (const auto& [lo, hi] : spans) {
      const std::vector<double> lines = roomLines(random, lo, hi);
      for (size_t k = 0; k + 1 < lines.size(); ++k) {
        Office office{};
        office.inside = {lines[k] + kHalfWall, lines[k + 1] - kHalfWall, band.z0 + kHalfWall,
                         band.z1 - kHalfWall};
        // The door keeps 0.8 m of wall on each side, away from the dividers.
        const double reach = 0.5 * kDoorWidth + 0.8;
        office.doorCentre = random.uniform(office.inside.x0 + reach, office.inside.x1 - reach);
        office.doorAtLowZ = band.doorAtLowZ;
        offices.push_back(office);
        if (k > 0) dividers.push_back({lines[k], &band});
      }
    }
  }

  FloorBuilder builder(scene, random, wallPatch);
  // Outer walls: those along x run the full width, those along z stop at them.
  builder.wallAlongX(-kHalfSize, -outer, outer, {});
  builder.wallAlongX(kHalfSize, -outer, outer, {});
  builder.wallAlongZ(-kHalfSize, -kHalfSize + kHalfWall, kHalfSize - kHalfWall);
  builder.wallAlongZ(kHalfSize, -kHalfSize + kHalfWall, kHalfSize - kHalfWall);

  // Interior walls along x with the offices' doors in them.
  auto doorsOn = [&](double z, double x0, double x1) {
    std::vector<double> doors;
    for (const Office& o : offices) {
      const double doorZ = o.doorAtLowZ ? o.inside.z0 - kHalfWall : o.inside.z1 + kHalfWall;
      if (std::abs(doorZ - z) < 1e-6 && o.doorCentre > x0 && o.doorCentre < x1)
        doors.push_back(o.doorCentre);
    }
    return doors;
  };
  const double inner = kHalfSize - kHalfWall;
  const double crossOuter = kCrossCorridor + kHalfWall;
  for (const double z : {-9.0, 9.0})
    builder.wallAlongX(z, -inner, inner, doorsOn(z, -inner, inner));
  for (const double z : {-7.0, 0.0, 7.0}) {
    builder.wallAlongX(z, -inner, -crossOuter, doorsOn(z, -inner, -crossOuter));
    builder.wallAlongX(z, crossOuter, inner, doorsOn(z, crossOuter, inner));
  }
  // The cross corridor's walls run through, closing the corners at z = +-7.
  for (const double x : {-kCrossCorridor, kCrossCorridor})
    builder.wallAlongZ(x, -7.0 - kHalfWall, 7.0 + kHalfWall);
  // Office dividers stop at the faces of the walls along x.
  for (const Divider& d : dividers)
    builder.wallAlongZ(d.x, d.band->z0 + kHalfWall, d.band->z1 - kHalfWall);

  for (const Office& office : offices) builder.furnish(office);
  return scene;
}

}  // namespace vistream
