// Tests of the procedural scenes (common/generate/generate.h): the counts the
// papers give, determinism by seed, the geometric conventions (closed boxes
// with outward faces, no degenerate or duplicated faces), free streets and
// connected free space, and the triangulated and OBJ forms of a scene.
#include "common/generate/generate.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <queue>
#include <set>
#include <sstream>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

#include "common/core/error.h"
#include "common/scene/scene_loader.h"

namespace vistream {
namespace {

bool startsWith(const std::string& s, const std::string& prefix) {
  return s.compare(0, prefix.size(), prefix) == 0;
}

// Twice the area times the unit normal (Newell's method): robust for any loop.
glm::dvec3 areaNormal(const PolygonObject& o, const std::vector<uint32_t>& face) {
  glm::dvec3 n(0.0);
  for (size_t i = 0; i < face.size(); ++i) {
    const glm::dvec3& a = o.vertices[face[i]];
    const glm::dvec3& b = o.vertices[face[(i + 1) % face.size()]];
    n +=
        glm::dvec3((a.y - b.y) * (a.z + b.z), (a.z - b.z) * (a.x + b.x), (a.x - b.x) * (a.y + b.y));
  }
  return n;
}

glm::dvec3 centroid(const PolygonObject& o, const std::vector<uint32_t>& face) {
  glm::dvec3 c(0.0);
  for (uint32_t v : face) c += o.vertices[v];
  return c / double(face.size());
}

Box3d boundsOf(const PolygonObject& o) {
  Box3d b;
  for (const glm::dvec3& v : o.vertices) b.extend(v);
  return b;
}

std::vector<const PolygonObject*> objectsNamed(const PolygonScene& scene,
                                               const std::string& prefix) {
  std::vector<const PolygonObject*> found;
  for (const PolygonObject& o : scene.objects)
    if (startsWith(o.name, prefix)) found.push_back(&o);
  return found;
}

// Faces [first, first + 6) of `o` form a closed box: six quads over 8
// vertices, every directed edge matched by its reverse, and every face's
// normal pointing away from the box centre.
::testing::AssertionResult isClosedOutwardBox(const PolygonObject& o, size_t first) {
  std::array<std::pair<uint32_t, uint32_t>, 24> edges;
  std::array<uint32_t, 24> corners;
  size_t e = 0;
  for (size_t f = first; f < first + 6; ++f) {
    if (o.faces[f].size() != 4)
      return ::testing::AssertionFailure() << o.name << " face " << f << " is not a quad";
    for (size_t i = 0; i < 4; ++i, ++e) {
      corners[e] = o.faces[f][i];
      edges[e] = {o.faces[f][i], o.faces[f][(i + 1) % 4]};
    }
  }
  std::sort(corners.begin(), corners.end());
  if (std::unique(corners.begin(), corners.end()) - corners.begin() != 8)
    return ::testing::AssertionFailure()
           << o.name << " box at face " << first << " does not use 8 vertices";
  for (const auto& [a, b] : edges)
    if (std::count(edges.begin(), edges.end(), std::pair{a, b}) != 1 ||
        std::count(edges.begin(), edges.end(), std::pair{b, a}) != 1)
      return ::testing::AssertionFailure()
             << o.name << " box at face " << first << " is not closed";
  glm::dvec3 centre(0.0);
  for (size_t k = 0; k < 8; ++k) centre += o.vertices[corners[k]];  // unique() moved them first
  centre /= 8.0;
  for (size_t f = first; f < first + 6; ++f)
    if (glm::dot(areaNormal(o, o.faces[f]), centroid(o, o.faces[f]) - centre) <= 0.0)
      return ::testing::AssertionFailure() << o.name << " face " << f << " points inward";
  return ::testing::AssertionSuccess();
}

// Every object whose name starts with one of `prefixes` is a sequence of closed boxes.
void expectBoxesClosedAndOutward(const PolygonScene& scene,
                                 const std::vector<std::string>& prefixes) {
  size_t boxes = 0;
  for (const PolygonObject& o : scene.objects) {
    if (std::none_of(prefixes.begin(), prefixes.end(),
                     [&](const std::string& p) { return startsWith(o.name, p); }))
      continue;
    ASSERT_EQ(o.faces.size() % 6, 0u) << o.name;
    for (size_t f = 0; f < o.faces.size(); f += 6, ++boxes) ASSERT_TRUE(isClosedOutwardBox(o, f));
  }
  EXPECT_GT(boxes, 0u);
}

void expectNoDegenerateFaces(const PolygonScene& scene) {
  for (const PolygonObject& o : scene.objects)
    for (size_t f = 0; f < o.faces.size(); ++f)
      ASSERT_GT(0.5 * glm::length(areaNormal(o, o.faces[f])), 1e-6) << o.name << " face " << f;
}

// Two faces with the same corner positions (in any order, on a millimetre
// grid) are duplicates. Faces here have at most four corners.
void expectNoDuplicatedFaces(const PolygonScene& scene) {
  using Key = std::array<int64_t, 12>;
  struct Hash {
    size_t operator()(const Key& key) const {
      uint64_t h = 1469598103934665603ull;
      for (int64_t k : key) h = (h ^ uint64_t(k)) * 1099511628211ull;
      return size_t(h ^ (h >> 29));
    }
  };
  std::unordered_set<Key, Hash> seen;
  seen.reserve(scene.faceCount());
  for (const PolygonObject& o : scene.objects)
    for (const std::vector<uint32_t>& face : o.faces) {
      ASSERT_LE(face.size(), 4u);
      std::array<std::array<int64_t, 3>, 4> corners;
      corners.fill({INT64_MAX, INT64_MAX, INT64_MAX});  // a triangle's missing fourth corner
      for (size_t i = 0; i < face.size() && i < 4; ++i) {
        const glm::dvec3 p = o.vertices[face[i]] * 1000.0;
        corners[i] = {std::llround(p.x), std::llround(p.y), std::llround(p.z)};
      }
      std::sort(corners.begin(), corners.end());
      Key key{};
      for (size_t i = 0; i < 4; ++i)
        for (size_t k = 0; k < 3; ++k) key[3 * i + k] = corners[i][k];
      ASSERT_TRUE(seen.insert(key).second) << "duplicated face in " << o.name;
    }
}

bool sameGeometry(const PolygonScene& a, const PolygonScene& b) {
  if (a.objects.size() != b.objects.size()) return false;
  for (size_t i = 0; i < a.objects.size(); ++i) {
    const PolygonObject &x = a.objects[i], &y = b.objects[i];
    if (x.name != y.name || x.vertices != y.vertices || x.faces != y.faces ||
        x.material != y.material)
      return false;
  }
  return true;
}

// Widths of the gaps between the intervals' union, strictly inside its span:
// the street corridors that cross a whole city along one axis.
std::vector<double> corridorWidths(std::vector<std::pair<double, double>> intervals) {
  std::sort(intervals.begin(), intervals.end());
  std::vector<double> gaps;
  double reach = intervals.front().second;
  for (const auto& [lo, hi] : intervals) {
    if (lo > reach) gaps.push_back(lo - reach);
    reach = std::max(reach, hi);
  }
  return gaps;
}

size_t countAtLeast(const std::vector<double>& values, double threshold) {
  return size_t(
      std::count_if(values.begin(), values.end(), [&](double v) { return v >= threshold; }));
}

// Footprints (x, z) whose interiors overlap, by sweeping along x.
size_t overlappingFootprints(std::vector<Box3d> boxes) {
  std::sort(boxes.begin(), boxes.end(),
            [](const Box3d& a, const Box3d& b) { return a.lo.x < b.lo.x; });
  size_t overlaps = 0;
  for (size_t i = 0; i < boxes.size(); ++i)
    for (size_t j = i + 1; j < boxes.size() && boxes[j].lo.x < boxes[i].hi.x; ++j)
      if (boxes[i].lo.z < boxes[j].hi.z && boxes[j].lo.z < boxes[i].hi.z) ++overlaps;
  return overlaps;
}

// ---- city1 and city2: Cohen-Or and Zadicario 1998, Table 1 -------------------

TEST(CityGenerator, City1HasThePapersBuildingAndPolygonCounts) {
  const PolygonScene city = generate("city1", 1);
  EXPECT_EQ(city.name, "city1");
  const auto buildings = objectsNamed(city, "building_");
  EXPECT_EQ(buildings.size(), 2128u);
  EXPECT_NEAR(double(city.faceCount()), 21280.0, 0.1 * 21280.0);
  // Two types: simple boxes, and about 25% of three stacked boxes.
  const auto stacked = std::count_if(buildings.begin(), buildings.end(),
                                     [](const PolygonObject* b) { return b->faces.size() == 18; });
  const auto simple = std::count_if(buildings.begin(), buildings.end(),
                                    [](const PolygonObject* b) { return b->faces.size() == 6; });
  EXPECT_EQ(stacked + simple, 2128);
  EXPECT_NEAR(double(stacked) / 2128.0, 0.25, 0.03);
}

TEST(CityGenerator, City2HasTheSamePolygonCountAsCity1) {
  const PolygonScene city = generate("city2", 1);
  EXPECT_EQ(objectsNamed(city, "building_").size(), 2128u);
  EXPECT_NEAR(double(city.faceCount()), 21280.0, 0.1 * 21280.0);
}

TEST(CityGenerator, SameSeedGivesTheSameCityAndAnotherSeedAnotherOne) {
  EXPECT_TRUE(sameGeometry(generate("city1", 7), generate("city1", 7)));
  EXPECT_FALSE(sameGeometry(generate("city1", 7), generate("city1", 8)));
  EXPECT_TRUE(sameGeometry(generate("city2", 7), generate("city2", 7)));
  EXPECT_FALSE(sameGeometry(generate("city2", 7), generate("city2", 8)));
}

TEST(CityGenerator, BuildingsAreClosedBoxesFacingOutwardOnAGroundFacingUp) {
  for (const char* type : {"city1", "city2"}) {
    SCOPED_TRACE(type);
    const PolygonScene city = generate(type, 1);
    expectBoxesClosedAndOutward(city, {"building_"});
    expectNoDegenerateFaces(city);
    expectNoDuplicatedFaces(city);
    const auto ground = objectsNamed(city, "ground");
    ASSERT_EQ(ground.size(), 1u);
    EXPECT_EQ(ground[0]->faces.size(), 2128u);  // one tile per lot
    for (const auto& face : ground[0]->faces) {
      const glm::dvec3 n = areaNormal(*ground[0], face);
      EXPECT_GT(n.y, 0.0);
      EXPECT_EQ(centroid(*ground[0], face).y, 0.0);
    }
    for (const PolygonObject* b : objectsNamed(city, "building_"))
      EXPECT_EQ(boundsOf(*b).lo.y, 0.0);
  }
}

TEST(CityGenerator, StackedBuildingsAreThreeBoxesShrinkingUpward) {
  const PolygonScene city = generate("city1", 1);
  for (const PolygonObject* b : objectsNamed(city, "building_")) {
    if (b->faces.size() != 18) continue;
    Box3d below;
    for (size_t box = 0; box < 3; ++box) {
      Box3d part;
      for (size_t v = 8 * box; v < 8 * box + 8; ++v) part.extend(b->vertices[v]);
      if (box > 0) {
        EXPECT_EQ(part.lo.y, below.hi.y) << b->name;  // stands on the box below
        EXPECT_GT(part.lo.x, below.lo.x) << b->name;
        EXPECT_LT(part.hi.x, below.hi.x) << b->name;
        EXPECT_GT(part.lo.z, below.lo.z) << b->name;
        EXPECT_LT(part.hi.z, below.hi.z) << b->name;
      }
      below = part;
    }
  }
}

TEST(CityGenerator, BuildingsNeitherOverlapNorBlockTheStreets) {
  for (const char* type : {"city1", "city2"}) {
    SCOPED_TRACE(type);
    const PolygonScene city = generate(type, 1);
    std::vector<Box3d> footprints;
    std::vector<std::pair<double, double>> alongX, alongZ;
    for (const PolygonObject* b : objectsNamed(city, "building_")) {
      const Box3d box = boundsOf(*b);
      footprints.push_back(box);
      alongX.emplace_back(box.lo.x, box.hi.x);
      alongZ.emplace_back(box.lo.z, box.hi.z);
    }
    EXPECT_EQ(overlappingFootprints(footprints), 0u);
    // 56 x 38 lots: 55 streets cross the city along z and 37 along x, each
    // at least 6 m wide and free of buildings over their whole length.
    EXPECT_GE(countAtLeast(corridorWidths(alongX), 6.0), 55u);
    EXPECT_GE(countAtLeast(corridorWidths(alongZ), 6.0), 37u);
  }
}

TEST(CityGenerator, City1IsDenserThanCity2) {
  auto builtUpFraction = [](const PolygonScene& city) {
    double built = 0.0;
    for (const PolygonObject* b : objectsNamed(city, "building_")) {
      const glm::dvec3 e = boundsOf(*b).extent();
      built += e.x * e.z;
    }
    const glm::dvec3 e = boundsOf(*objectsNamed(city, "ground")[0]).extent();
    return built / (e.x * e.z);
  };
  const double dense = builtUpFraction(generate("city1", 1));
  const double sparse = builtUpFraction(generate("city2", 1));
  EXPECT_GT(dense, 0.3);
  EXPECT_LT(sparse, 0.2);
  EXPECT_GT(dense, 2.0 * sparse);
}

// ---- bigcity: Wimmer 2001, 2.1 million polygons over 4 km^2 ------------------

const PolygonScene& bigCity() {
  static const PolygonScene scene = generate("bigcity", 1);
  return scene;
}

TEST(BigCityGenerator, HasTwoMillionTrianglesOverFourSquareKilometres) {
  const Scene scene = toScene(bigCity());
  EXPECT_GE(scene.triangleCount(), 2'000'000u);
  EXPECT_EQ(scene.diagnostics.degenerateTriangles, 0u);
  const Box3d bounds = scene.fileBounds();
  EXPECT_NEAR(bounds.extent().x, 2000.0, 100.0);
  EXPECT_NEAR(bounds.extent().z, 2000.0, 100.0);
  EXPECT_NEAR(bounds.lo.y, 0.0, 1e-3);
  const size_t buildings = objectsNamed(bigCity(), "building_").size();
  EXPECT_GE(buildings, 2000u);
  EXPECT_LE(buildings, 6000u);
}

TEST(BigCityGenerator, AnotherSeedGivesAnotherCityStillAboveTwoMillionTriangles) {
  const PolygonScene other = generate("bigcity", 2);
  EXPECT_FALSE(sameGeometry(bigCity(), other));
  size_t triangles = 0;
  for (const PolygonObject& o : other.objects)
    for (const auto& face : o.faces) triangles += face.size() - 2;
  EXPECT_GE(triangles, 2'000'000u);
  EXPECT_TRUE(sameGeometry(other, generate("bigcity", 2)));
}

TEST(BigCityGenerator, EveryBuildingPieceIsAClosedBoxFacingOutward) {
  expectBoxesClosedAndOutward(bigCity(), {"building_", "windows_", "monument_"});
  expectNoDegenerateFaces(bigCity());
  expectNoDuplicatedFaces(bigCity());
  for (const char* ground : {"streets", "block_ground"}) {
    const auto found = objectsNamed(bigCity(), ground);
    ASSERT_EQ(found.size(), 1u) << ground;
    for (const auto& face : found[0]->faces) EXPECT_GT(areaNormal(*found[0], face).y, 0.0);
  }
}

TEST(BigCityGenerator, StreetsAreFreeOfGeometryAndBuildingsDoNotOverlap) {
  // A building is its body and its windows.
  std::map<std::string, Box3d> buildings;
  std::vector<std::pair<double, double>> alongX, alongZ;
  for (const PolygonObject& o : bigCity().objects) {
    if (o.name == "streets" || o.name == "block_ground") continue;
    const Box3d box = boundsOf(o);
    alongX.emplace_back(box.lo.x, box.hi.x);
    alongZ.emplace_back(box.lo.z, box.hi.z);
    const size_t underscore = o.name.find('_');
    if (startsWith(o.name, "building_") || startsWith(o.name, "windows_"))
      buildings[o.name.substr(underscore + 1)].extend(box);
  }
  std::vector<Box3d> footprints;
  for (const auto& [number, box] : buildings) footprints.push_back(box);
  EXPECT_EQ(overlappingFootprints(footprints), 0u);
  // 18 x 18 blocks: 17 inner streets along each axis, at least 10 m wide.
  EXPECT_GE(countAtLeast(corridorWidths(alongX), 10.0), 17u);
  EXPECT_GE(countAtLeast(corridorWidths(alongZ), 10.0), 17u);
}

// ---- interior: Bittner and Havran 2001, scene I --------------------------------

TEST(InteriorGenerator, Interior2IsTheSameFloorWithWallsCutIntoPatchesOfAtMostTwoMetres) {
  const PolygonScene whole = generate("interior", 1), patched = generate("interior2", 1);
  double wholeLength = 0.0, patchedLength = 0.0;
  for (const auto* w : objectsNamed(whole, "wall_")) {
    const glm::dvec3 e = boundsOf(*w).extent();
    wholeLength += std::max(e.x, e.z);
  }
  for (const auto* w : objectsNamed(patched, "wall_")) {
    const glm::dvec3 e = boundsOf(*w).extent();
    EXPECT_LE(std::max(e.x, e.z), 2.0 + 1e-9) << w->name;
    patchedLength += std::max(e.x, e.z);
  }
  EXPECT_NEAR(patchedLength, wholeLength, 1e-6);  // cut, not moved
  EXPECT_GT(objectsNamed(patched, "wall_").size(), 3 * objectsNamed(whole, "wall_").size());
  EXPECT_EQ(objectsNamed(patched, "chair_").size(), objectsNamed(whole, "chair_").size());
}

TEST(InteriorGenerator, HasFloorCeilingWallsAndDoorsOnOneStorey) {
  const PolygonScene floor = generate("interior", 1);
  const auto floors = objectsNamed(floor, "floor"), ceilings = objectsNamed(floor, "ceiling");
  ASSERT_EQ(floors.size(), 1u);
  ASSERT_EQ(ceilings.size(), 1u);
  for (const auto& face : floors[0]->faces) {
    EXPECT_GT(areaNormal(*floors[0], face).y, 0.0);
    EXPECT_EQ(centroid(*floors[0], face).y, 0.0);
  }
  for (const auto& face : ceilings[0]->faces) {
    EXPECT_LT(areaNormal(*ceilings[0], face).y, 0.0);
    EXPECT_EQ(centroid(*ceilings[0], face).y, 3.0);
  }
  const glm::dvec3 extent = boundsOf(*floors[0]).extent();
  EXPECT_NEAR(extent.x, 40.0, 1.0);
  EXPECT_NEAR(extent.z, 40.0, 1.0);

  const auto walls = objectsNamed(floor, "wall_");
  EXPECT_GE(walls.size(), 40u);
  for (const PolygonObject* w : walls) {
    const Box3d b = boundsOf(*w);
    EXPECT_EQ(b.lo.y, 0.0);
    EXPECT_EQ(b.hi.y, 3.0);
    EXPECT_NEAR(std::min(b.extent().x, b.extent().z), 0.2, 1e-9) << w->name;
  }
  // Every door is a 1 m wide, 2.1 m high opening under a lintel.
  const auto lintels = objectsNamed(floor, "lintel_");
  EXPECT_GE(lintels.size(), 20u);
  for (const PolygonObject* l : lintels) {
    const Box3d lintel = boundsOf(*l);
    EXPECT_NEAR(lintel.lo.y, 2.1, 1e-9);
    EXPECT_NEAR(std::max(lintel.extent().x, lintel.extent().z), 1.0, 1e-9);
    const glm::dvec3 doorway(lintel.center().x, 1.0, lintel.center().z);
    for (const PolygonObject& o : floor.objects)
      if (&o != floors[0] && &o != ceilings[0]) {
        EXPECT_FALSE(boundsOf(o).contains(doorway)) << o.name << " blocks " << l->name;
      }
  }
}

struct FloodFill {
  size_t freePoints = 0;
  size_t reached = 0;
  size_t gridPoints = 0;
};

// Flood fill over a 0.25 m grid of points 1 m above the floor, inside the
// outer walls. Points inside an obstacle (any object reaching 1 m height
// but floor and ceiling) are not free; a step between neighbours is blocked
// if its segment touches an obstacle, as walls are thinner than the grid.
FloodFill floodFillAtChestHeight(const PolygonScene& floor) {
  std::vector<Box3d> obstacles;
  for (const PolygonObject& o : floor.objects) {
    const Box3d b = boundsOf(o);
    if (o.name != "floor" && o.name != "ceiling" && b.lo.y <= 1.0 && b.hi.y >= 1.0)
      obstacles.push_back(b);
  }
  constexpr int n = 160;
  auto coordinate = [](int i) { return -19.875 + 0.25 * i; };
  FloodFill result;
  result.gridPoints = size_t(n) * n;
  std::vector<uint8_t> free(result.gridPoints, 1);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const glm::dvec3 p(coordinate(i), 1.0, coordinate(j));
      free[j * n + i] = std::none_of(obstacles.begin(), obstacles.end(),
                                     [&](const Box3d& b) { return b.contains(p); });
      result.freePoints += free[j * n + i];
    }
  auto stepBlocked = [&](int i0, int j0, int i1, int j1) {
    const double x0 = coordinate(std::min(i0, i1)), x1 = coordinate(std::max(i0, i1));
    const double z0 = coordinate(std::min(j0, j1)), z1 = coordinate(std::max(j0, j1));
    return std::any_of(obstacles.begin(), obstacles.end(), [&](const Box3d& b) {
      return b.lo.x <= x1 && b.hi.x >= x0 && b.lo.z <= z1 && b.hi.z >= z0;
    });
  };
  int start = 0;
  while (!free[start]) ++start;
  std::vector<uint8_t> reached(result.gridPoints, 0);
  std::queue<int> frontier;
  frontier.push(start);
  reached[start] = 1;
  result.reached = 1;
  while (!frontier.empty()) {
    const int cell = frontier.front();
    frontier.pop();
    const int i = cell % n, j = cell / n;
    for (const auto& [di, dj] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
      const int ni = i + di, nj = j + dj;
      if (ni < 0 || nj < 0 || ni >= n || nj >= n) continue;
      const int next = nj * n + ni;
      if (!free[next] || reached[next] || stepBlocked(i, j, ni, nj)) continue;
      reached[next] = 1;
      ++result.reached;
      frontier.push(next);
    }
  }
  return result;
}

TEST(InteriorGenerator, FreeSpaceAtChestHeightIsConnectedThroughTheDoors) {
  for (const uint64_t seed : {1u, 2u, 3u, 4u}) {
    SCOPED_TRACE(seed);
    const FloodFill fill = floodFillAtChestHeight(generate("interior", seed));
    EXPECT_GT(fill.freePoints,
              size_t(0.7 * double(fill.gridPoints)));  // most of the floor is walkable
    EXPECT_EQ(fill.reached, fill.freePoints);          // and all of it one connected space
  }
}

TEST(InteriorGenerator, WallsDoNotOverlapAndFurnitureStandsOnTheFloorBetweenThem) {
  for (const uint64_t seed : {1u, 2u, 3u, 4u}) {
    SCOPED_TRACE(seed);
    const PolygonScene floor = generate("interior", seed);
    expectBoxesClosedAndOutward(floor, {"wall_", "lintel_", "table_", "chair_", "desk_", "shelf_"});
    expectNoDegenerateFaces(floor);
    expectNoDuplicatedFaces(floor);
    std::vector<Box3d> structure;
    for (const PolygonObject& o : floor.objects)
      if (startsWith(o.name, "wall_") || startsWith(o.name, "lintel_"))
        structure.push_back(boundsOf(o));
    auto interiorsOverlap = [](const Box3d& a, const Box3d& b) {
      return a.lo.x < b.hi.x && b.lo.x < a.hi.x && a.lo.y < b.hi.y && b.lo.y < a.hi.y &&
             a.lo.z < b.hi.z && b.lo.z < a.hi.z;
    };
    for (size_t i = 0; i < structure.size(); ++i)
      for (size_t j = i + 1; j < structure.size(); ++j)
        EXPECT_FALSE(interiorsOverlap(structure[i], structure[j])) << i << " and " << j;
    size_t furniture = 0;
    for (const PolygonObject& o : floor.objects) {
      if (!startsWith(o.name, "table_") && !startsWith(o.name, "chair_") &&
          !startsWith(o.name, "desk_") && !startsWith(o.name, "shelf_"))
        continue;
      ++furniture;
      const Box3d b = boundsOf(o);
      EXPECT_EQ(b.lo.y, 0.0) << o.name;
      for (const Box3d& wall : structure) EXPECT_FALSE(interiorsOverlap(b, wall)) << o.name;
    }
    EXPECT_GE(furniture, 100u);
  }
}

TEST(InteriorGenerator, SameSeedGivesTheSameFloorAndAnotherSeedAnotherOne) {
  EXPECT_TRUE(sameGeometry(generate("interior", 3), generate("interior", 3)));
  EXPECT_FALSE(sameGeometry(generate("interior", 3), generate("interior", 4)));
}

// ---- terrain -------------------------------------------------------------------

TEST(TerrainGenerator, IsOpenToTheSkyWithNothingAboveTheCentre) {
  const PolygonScene land = generate("terrain", 1);
  expectNoDegenerateFaces(land);
  expectNoDuplicatedFaces(land);
  expectBoxesClosedAndOutward(land, {"tree_", "rock_"});
  size_t terrainFaces = 0;
  for (const PolygonObject& o : land.objects) {
    if (startsWith(o.name, "terrain_")) {
      // A heightfield: every face looks at the sky, nothing overhangs.
      for (const auto& face : o.faces) ASSERT_GT(areaNormal(o, face).y, 0.0) << o.name;
      terrainFaces += o.faces.size();
    } else {
      const Box3d b = boundsOf(o);
      EXPECT_FALSE(b.lo.x <= 0.0 && b.hi.x >= 0.0 && b.lo.z <= 0.0 && b.hi.z >= 0.0)
          << o.name << " covers the centre";
    }
  }
  EXPECT_EQ(terrainFaces, 2u * 256u * 256u);
}

TEST(TerrainGenerator, HasWalkableHillsInTheMiddleAndMountainsAtTheBorder) {
  for (const uint64_t seed : {1u, 2u, 3u}) {
    SCOPED_TRACE(seed);
    const PolygonScene land = generate("terrain", seed);
    double middleSum = 0.0, borderSum = 0.0, steepestMiddle = 0.0, highest = 0.0;
    size_t middle = 0, border = 0;
    for (const PolygonObject* o : objectsNamed(land, "terrain_")) {
      for (const auto& face : o->faces) {
        const glm::dvec3 c = centroid(*o, face), n = areaNormal(*o, face);
        const double r = std::hypot(c.x, c.z);
        highest = std::max(highest, c.y);
        if (r < 600.0) {
          middleSum += c.y;
          ++middle;
          steepestMiddle = std::max(steepestMiddle, std::hypot(n.x, n.z) / n.y);
        } else if (r > 1800.0) {
          borderSum += c.y;
          ++border;
        }
      }
    }
    EXPECT_LT(steepestMiddle, 0.3);  // walkable
    EXPECT_GT(borderSum / double(border), middleSum / double(middle) + 150.0);
    EXPECT_GT(highest, 300.0);
  }
}

TEST(TerrainGenerator, SameSeedGivesTheSameLandAndAnotherSeedAnotherOne) {
  EXPECT_TRUE(sameGeometry(generate("terrain", 5), generate("terrain", 5)));
  EXPECT_FALSE(sameGeometry(generate("terrain", 5), generate("terrain", 6)));
}

// ---- dispatch ------------------------------------------------------------------

TEST(SceneTypes, ListsTheSixGeneratorsAndEachGeneratesANamedScene) {
  EXPECT_EQ(sceneTypes(), (std::vector<std::string>{"city1", "city2", "bigcity", "interior",
                                                    "interior2", "terrain"}));
  for (const char* type : {"city1", "interior", "terrain"}) {
    const PolygonScene scene = generate(type, 1);
    EXPECT_EQ(scene.name, type);
    EXPECT_FALSE(scene.materials.empty());
    for (const PolygonObject& o : scene.objects)
      EXPECT_LT(o.material, scene.materials.size()) << o.name;
  }
}

TEST(SceneTypes, RejectsAnUnknownTypeWithAnInputError) {
  EXPECT_THROW(generate("castle", 1), InputError);
}

// ---- toScene -------------------------------------------------------------------

TEST(ToScene, GivesFaceIdsInObjectThenFaceOrderWithNMinusTwoTrianglesEach) {
  for (const char* type : {"interior", "terrain"}) {
    SCOPED_TRACE(type);
    const PolygonScene polygons = generate(type, 1);
    const Scene scene = toScene(polygons);
    ASSERT_EQ(scene.objects.size(), polygons.objects.size());
    EXPECT_EQ(scene.faceCount, polygons.faceCount());
    EXPECT_EQ(scene.diagnostics.degenerateTriangles, 0u);
    uint32_t firstFace = 0;
    size_t expectedTriangles = 0;
    for (size_t oi = 0; oi < polygons.objects.size(); ++oi) {
      const PolygonObject& source = polygons.objects[oi];
      const Object& object = scene.objects[oi];
      EXPECT_EQ(object.name, source.name);
      std::vector<uint32_t> expected;  // face ID per triangle: face f gives n-2
      for (size_t f = 0; f < source.faces.size(); ++f)
        expected.insert(expected.end(), source.faces[f].size() - 2, firstFace + uint32_t(f));
      EXPECT_EQ(object.mesh.faceIds, expected) << source.name;
      expectedTriangles += expected.size();
      for (uint32_t m : object.mesh.materials) EXPECT_EQ(m, source.material);
      // Positions are the file coordinates relative to the origin, in float.
      ASSERT_EQ(object.mesh.positions.size(), source.vertices.size());
      for (size_t v = 0; v < source.vertices.size(); ++v)
        ASSERT_LT(glm::length(scene.toFile(object.mesh.positions[v]) - source.vertices[v]), 1e-3);
      firstFace += uint32_t(source.faces.size());
    }
    EXPECT_EQ(scene.triangleCount(), expectedTriangles);
    ASSERT_EQ(scene.materials.size(), polygons.materials.size());
    for (size_t m = 0; m < polygons.materials.size(); ++m)
      EXPECT_EQ(scene.materials[m].name, polygons.materials[m].name);
  }
}

TEST(ToScene, PutsTheOriginAtTheCentreOfTheBoundsAndKeepsTheDynamicFlag) {
  PolygonScene polygons;
  polygons.name = "far away";
  PolygonObject pentagon;
  pentagon.name = "pentagon";
  pentagon.dynamic = true;
  const glm::dvec3 far(5.0e6, 10.0, -3.0e6);
  for (int k = 0; k < 5; ++k) {
    const double a = 2.0 * 3.141592653589793 * k / 5.0;
    pentagon.vertices.push_back(far + glm::dvec3(std::cos(a), 0.0, -std::sin(a)));
  }
  pentagon.faces.push_back({0, 1, 2, 3, 4});
  polygons.objects.push_back(pentagon);
  const Scene scene = toScene(polygons);
  ASSERT_EQ(scene.objects.size(), 1u);
  EXPECT_TRUE(scene.objects[0].dynamic);
  EXPECT_EQ(scene.objects[0].mesh.triangleCount(), 3u);
  EXPECT_EQ(scene.objects[0].mesh.faceIds, (std::vector<uint32_t>{0, 0, 0}));
  EXPECT_EQ(scene.faceCount, 1u);
  EXPECT_FALSE(scene.materials.empty());
  Box3d bounds;
  for (const glm::dvec3& v : pentagon.vertices) bounds.extend(v);
  EXPECT_EQ(scene.origin, bounds.center());
  for (size_t v = 0; v < 5; ++v)  // sub-millimetre although 5,000 km out
    EXPECT_LT(glm::length(scene.toFile(scene.objects[0].mesh.positions[v]) - pentagon.vertices[v]),
              1e-6);
}

// ---- writeObj ------------------------------------------------------------------

struct ObjContents {
  std::string mtllib;
  std::vector<std::string> objectNames;
  std::vector<std::string> usedMaterials;
  std::vector<glm::dvec3> vertices;
  std::vector<std::vector<size_t>> faces;  // 1-based as written
};

// Just enough of an OBJ reader to check what writeObj promises.
ObjContents readObj(const std::filesystem::path& path) {
  ObjContents obj;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string keyword;
    fields >> keyword;
    if (keyword == "v") {
      std::string x, y, z;
      fields >> x >> y >> z;
      obj.vertices.emplace_back(std::strtod(x.c_str(), nullptr), std::strtod(y.c_str(), nullptr),
                                std::strtod(z.c_str(), nullptr));
    } else if (keyword == "f") {
      std::vector<size_t> face;
      size_t index = 0;
      while (fields >> index) face.push_back(index);
      obj.faces.push_back(face);
    } else if (keyword == "o") {
      obj.objectNames.emplace_back();
      fields >> obj.objectNames.back();
    } else if (keyword == "usemtl") {
      obj.usedMaterials.emplace_back();
      fields >> obj.usedMaterials.back();
    } else if (keyword == "mtllib") {
      fields >> obj.mtllib;
    }
  }
  return obj;
}

class WriteObj : public ::testing::Test {
 protected:
  void SetUp() override {
    directory_ = std::filesystem::temp_directory_path() /
                 ("vistream_generate_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(directory_);
  }
  void TearDown() override { std::filesystem::remove_all(directory_); }

  // A generated scene and the OBJ file writeObj made of it.
  struct Written {
    PolygonScene polygons;
    std::filesystem::path path;
  };
  // Generates `type` (seed 1) and writes it as <type>.obj in the test's directory.
  Written generateAndWrite(const std::string& type) const {
    Written w{generate(type, 1), directory_ / (type + ".obj")};
    writeObj(w.polygons, w.path);
    return w;
  }

  std::filesystem::path directory_;
};

TEST_F(WriteObj, RoundTripsObjectsFacesAndVerticesThroughAMinimalReader) {
  for (const char* type : {"city1", "interior"}) {
    SCOPED_TRACE(type);
    const auto [polygons, path] = generateAndWrite(type);
    const ObjContents obj = readObj(path);

    EXPECT_EQ(obj.mtllib, std::string(type) + ".mtl");
    ASSERT_EQ(obj.objectNames.size(), polygons.objects.size());
    ASSERT_EQ(obj.faces.size(), polygons.faceCount());
    size_t vertex = 0, face = 0;
    for (size_t oi = 0; oi < polygons.objects.size(); ++oi) {
      const PolygonObject& o = polygons.objects[oi];
      EXPECT_EQ(obj.objectNames[oi], o.name);
      const size_t first = vertex + 1;
      for (const glm::dvec3& v : o.vertices) {
        const glm::dvec3 read = obj.vertices[vertex++];
        for (int k = 0; k < 3; ++k)
          ASSERT_LE(std::abs(read[k] - v[k]), 1e-9 * std::max(1.0, std::abs(v[k])));
      }
      for (const auto& loop : o.faces) {
        std::vector<size_t> expected;
        for (uint32_t index : loop) expected.push_back(first + index);
        ASSERT_EQ(obj.faces[face++], expected) << o.name;
      }
    }
    EXPECT_EQ(vertex, obj.vertices.size());

    // Every material used is defined in the .mtl with its diffuse colour.
    std::ifstream mtl(directory_ / obj.mtllib);
    ASSERT_TRUE(mtl.good());
    std::set<std::string> defined;
    std::string keyword, name;
    size_t diffuse = 0;
    while (mtl >> keyword) {
      if (keyword == "newmtl" && mtl >> name) defined.insert(name);
      if (keyword == "Kd") ++diffuse;
    }
    EXPECT_EQ(defined.size(), polygons.materials.size());
    EXPECT_EQ(diffuse, polygons.materials.size());
    for (const std::string& used : obj.usedMaterials) EXPECT_TRUE(defined.count(used)) << used;
    EXPECT_FALSE(obj.usedMaterials.empty());
  }
}

TEST_F(WriteObj, LoadingTheWrittenFileGivesTheSameFacesAsToScene) {
  for (const char* type : {"city1", "interior"}) {
    SCOPED_TRACE(type);
    const auto [polygons, path] = generateAndWrite(type);
    const Scene direct = toScene(polygons);
    const Scene loaded = loadObj(path);
    EXPECT_EQ(loaded.faceCount, direct.faceCount);
    EXPECT_EQ(loaded.triangleCount(), direct.triangleCount());
    ASSERT_EQ(loaded.objects.size(), direct.objects.size());
    for (size_t i = 0; i < direct.objects.size(); ++i) {
      EXPECT_EQ(loaded.objects[i].name, direct.objects[i].name);
      EXPECT_EQ(loaded.objects[i].mesh.faceIds, direct.objects[i].mesh.faceIds)
          << direct.objects[i].name;
    }
    const Box3d a = direct.fileBounds(), b = loaded.fileBounds();
    EXPECT_LT(glm::length(a.lo - b.lo) + glm::length(a.hi - b.hi), 1e-3);
  }
}

TEST_F(WriteObj, ReplacesTheFileWithoutLeavingATemporaryBehind) {
  const std::filesystem::path path = directory_ / "scene.obj";
  { std::ofstream(path) << "old contents\n"; }
  writeObj(generate("interior", 2), path);
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(directory_))
    names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"scene.mtl", "scene.obj"}));
  EXPECT_EQ(readObj(path).faces.size(), generate("interior", 2).faceCount());
}

TEST_F(WriteObj, ThrowsAnInputErrorWhenTheDirectoryDoesNotExist) {
  EXPECT_THROW(writeObj(generate("interior", 1), directory_ / "missing" / "scene.obj"), InputError);
}

}  // namespace
}  // namespace vistream
