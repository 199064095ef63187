#include "common/generate/path.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include "common/core/error.h"
#include "common/generate/scene_spec.h"
#include "common/raycast/sampled_visibility.h"
#include "common/world/static_world.h"
#include "tests/common/support/box_scenes.h"

namespace vistream {
namespace {

using testing::addBox;
using testing::addGround;

// A small town: ground and a 4 x 4 grid of buildings with 8 m streets,
// placed 50 km from the origin to exercise the local frame.
struct Town {
  Scene scene;
  FlatTriangles triangles;
  std::unique_ptr<RayQuery> rays;
  std::unique_ptr<RayQuery> oracle;
  FreeSpace freeSpace;
  std::vector<Box3f> buildings;

  Town() {
    scene.origin = {50000.0, 0.0, -50000.0};
    addGround(scene, -40, -40, 40, 40);
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < 4; ++k) {
        const glm::vec3 lo(-36.0f + 20.0f * float(i), 0.0f, -36.0f + 20.0f * float(k));
        const glm::vec3 hi = lo + glm::vec3(12.0f, 6.0f + float(i + k), 12.0f);
        addBox(scene, "b", lo, hi);
        buildings.emplace_back(lo, hi);
      }
    finalizeScene(scene);
    triangles = flattenScene(scene);
    rays = makeEmbreeRayQuery(triangles);
    oracle = makeBruteForceRayQuery(triangles);
    freeSpace = FreeSpace::build(*rays, Solids::build(triangles), scene.bounds());
  }
};

const Town& town() {
  static const Town t;
  return t;
}

std::vector<PathSample> walk(double speed, size_t frames, uint64_t seed) {
  PathOptions o;
  o.speed = speed;
  o.frames = frames;
  o.seed = seed;
  return generatePath(town().scene, town().freeSpace, o);
}

TEST(WalkthroughPath, StaysAtEyeHeightAboveTheGroundInTheStreets) {
  const auto path = walk(1.0, 600, 1);
  ASSERT_EQ(path.size(), 600u);
  for (const auto& s : path) {
    const glm::vec3 p = town().scene.toLocal(s.position);
    const Hit down = town().oracle->firstHit(Ray{p, {0, -1, 0}, 0.0f, 100.0f});
    ASSERT_TRUE(down.valid());
    EXPECT_NEAR(down.t, 1.7f, 1e-3f);
    EXPECT_GT(down.normal.y, 0.0f);  // standing on an upward-facing floor
    for (const Box3f& b : town().buildings)
      EXPECT_FALSE(p.x > b.lo.x && p.x < b.hi.x && p.z > b.lo.z && p.z < b.hi.z);
  }
}

// Crossings of a ray with one object's triangles (Moller-Trumbore, two-sided),
// written here so the oracle shares no code with common/world.
int crossings(const Object& o, const glm::dvec3& org, const glm::dvec3& dir) {
  int n = 0;
  for (const glm::uvec3& t : o.mesh.triangles) {
    const glm::dvec3 a(o.mesh.positions[t.x]), b(o.mesh.positions[t.y]), c(o.mesh.positions[t.z]);
    const glm::dvec3 e1 = b - a, e2 = c - a, p = glm::cross(dir, e2);
    const double det = glm::dot(e1, p);
    if (std::abs(det) < 1e-12) continue;
    const glm::dvec3 s = org - a;
    const double u = glm::dot(s, p) / det;
    const glm::dvec3 q = glm::cross(s, e1);
    const double v = glm::dot(dir, q) / det, t2 = glm::dot(e2, q) / det;
    if (u >= 0 && v >= 0 && u + v <= 1 && t2 > 0) ++n;
  }
  return n;
}

// The oracle for columnsNearObstacles: every column of the square of side
// 2r + 1 around a walkable column, looked at one by one.
bool nearObstacleByScan(const FreeSpace& fs, glm::ivec2 c, double reach) {
  const int r = int(std::ceil(reach / double(fs.cellSize())));
  for (int k = std::max(0, c.y - r); k <= std::min(fs.columnsZ() - 1, c.y + r); ++k)
    for (int i = std::max(0, c.x - r); i <= std::min(fs.columnsX() - 1, c.x + r); ++i)
      if (!fs.walkable(i, k)) return true;
  return false;
}

TEST(WalkthroughPath, ColumnsNearObstaclesAreTheWalkableOnesWithABlockedColumnInReach) {
  const FreeSpace& fs = town().freeSpace;
  // Beyond the town's size every walkable column is near one of its buildings.
  EXPECT_EQ(columnsNearObstacles(fs, 200.0).size(), fs.walkableCount());
  for (const double reach : {0.0, 0.5, 3.0, 12.0}) {
    SCOPED_TRACE("reach " + std::to_string(reach));
    const std::vector<glm::ivec2> near = columnsNearObstacles(fs, reach);
    std::vector<glm::ivec2> want;
    for (const glm::ivec2& c : fs.walkableColumns())
      if (nearObstacleByScan(fs, c, reach)) want.push_back(c);
    ASSERT_EQ(near.size(), want.size());
    for (size_t i = 0; i < near.size(); ++i) ASSERT_EQ(near[i], want[i]) << "column " << i;
    if (reach == 0.0) {
      EXPECT_TRUE(near.empty());
    }
    if (reach == 3.0) {
      EXPECT_GT(near.size(), 0u);
      EXPECT_LT(near.size(), fs.walkableCount()) << "the middle of the 8 m streets is farther";
    }
  }
}

// The oracle for obstacleDensity: the columns of the square around c
// counted one by one.
float densityByScan(const FreeSpace& fs, glm::ivec2 c, double radius) {
  const int r = int(std::ceil(radius / double(fs.cellSize())));
  int blocked = 0, all = 0;
  for (int k = std::max(0, c.y - r); k <= std::min(fs.columnsZ() - 1, c.y + r); ++k)
    for (int i = std::max(0, c.x - r); i <= std::min(fs.columnsX() - 1, c.x + r); ++i) {
      blocked += !fs.walkable(i, k);
      ++all;
    }
  return float(blocked) / float(all);
}

TEST(WalkthroughPath, ObstacleDensityIsTheShareOfUnwalkableColumnsAround) {
  const FreeSpace& fs = town().freeSpace;
  const std::vector<glm::ivec2> columns = fs.walkableColumns();
  for (const double radius : {0.0, 1.0, 10.0}) {
    const std::vector<float> density = obstacleDensity(fs, radius);
    ASSERT_EQ(density.size(), columns.size());
    for (size_t c = 0; c < columns.size(); c += 97)
      ASSERT_FLOAT_EQ(density[c], densityByScan(fs, columns[c], radius))
          << "radius " << radius << " column " << columns[c].x << "," << columns[c].y;
    if (radius == 0.0) {
      EXPECT_EQ(*std::max_element(density.begin(), density.end()), 0.0f);
    }
  }
}

TEST(WalkthroughPath, StartsAmongDelfshavensBuildingsButNotAgainstAWall) {
  const Scene scene = openScene(std::string(VISTREAM_SHARED_DIR) + "/data/delfshaven.obj");
  const StaticWorld world = buildStaticWorld(scene);
  const FreeSpace& fs = world.freeSpace;
  PathOptions o;
  o.frames = 1;
  // The density of an even sample of the walkable columns: much of the
  // assumed ground around the city has no building near at all.
  const std::vector<glm::ivec2> columns = fs.walkableColumns();
  std::vector<float> sample;
  for (size_t c = 0; c < columns.size(); c += columns.size() / 400 + 1)
    sample.push_back(densityByScan(fs, columns[c], o.goalRadius));
  std::sort(sample.begin(), sample.end());
  EXPECT_EQ(sample[sample.size() / 10], 0.0f) << "a tenth of the ground has no obstacle around";
  const float quartile = sample[sample.size() / 4];
  for (uint64_t seed = 1; seed <= 8; ++seed) {
    o.seed = seed;
    const glm::vec3 start = scene.toLocal(generatePath(scene, fs, o).front().position);
    const glm::ivec2 column = fs.columnOf({start.x, start.z});
    EXPECT_GT(densityByScan(fs, column, o.goalRadius), quartile) << "seed " << seed;
    EXPECT_FALSE(nearObstacleByScan(fs, column, o.goalClearance))
        << "seed " << seed << ": a walk should not start with its nose at a wall";
  }
}

TEST(WalkthroughPath, WalksDelfshavensStreetsOnTheAssumedGroundOutsideEveryBuilding) {
  // Buildings only, no terrain (../shared/data/README.md: ground at y = 0).
  const Scene scene = openScene(std::string(VISTREAM_SHARED_DIR) + "/data/delfshaven.obj");
  const StaticWorld world = buildStaticWorld(scene);
  ASSERT_TRUE(world.ground.y.has_value()) << world.ground.why;
  EXPECT_NEAR(scene.origin.y + double(*world.ground.y), 0.0, 1e-3);
  PathOptions o;
  o.frames = 300;
  o.speed = 2.0;
  const auto path = generatePath(scene, world.freeSpace, o);
  const auto upRays = makeBruteForceRayQuery(*world.triangles);
  // Seven directions, none along a wall of the city grid nor vertical.
  const glm::dvec3 dirs[7] = {glm::normalize(glm::dvec3(0.8137, 0.0731, 0.5765)),
                              glm::normalize(glm::dvec3(-0.3319, 0.1123, 0.9366)),
                              glm::normalize(glm::dvec3(-0.7712, 0.2514, -0.3306)),
                              glm::normalize(glm::dvec3(0.2203, 0.4871, -0.8453)),
                              glm::normalize(glm::dvec3(0.9412, 0.1637, -0.2957)),
                              glm::normalize(glm::dvec3(-0.5138, 0.6022, 0.6111)),
                              glm::normalize(glm::dvec3(-0.9650, 0.0412, 0.2590))};
  for (size_t i = 0; i < path.size(); i += 3) {
    const glm::dvec3 file = path[i].position;
    EXPECT_NEAR(file.y, 1.7, 1e-3) << "frame " << i << ": eye height above the ground";
    const glm::vec3 local = scene.toLocal(file);
    // In the street: nothing overhead (no roof, no upper floor).
    EXPECT_FALSE(upRays->occluded(Ray{local, {0, 1, 0}, 0.0f, 1000.0f})) << "frame " << i;
    // Outside every building: most rays cross each building's own mesh an
    // even number of times (most, not all: 808 of the 853 meshes are open,
    // and one ray can slip through a crack and count one crossing short).
    for (const Object& b : scene.objects) {
      if (!b.bounds.contains(local)) continue;
      int odd = 0;
      for (const glm::dvec3& d : dirs) odd += crossings(b, glm::dvec3(local), d) % 2;
      EXPECT_LE(odd, 2) << "frame " << i << " in " << b.name;
    }
  }
}

TEST(WalkthroughPath, MovesAtTheRequestedSpeedWithoutPassingThroughWalls) {
  for (const double speed : {0.5, 1.0, 3.0}) {
    const auto path = walk(speed, 300, 2);
    const double step = kWalkingSpeed * speed / 30.0;
    double total = 0.0;
    for (size_t i = 1; i < path.size(); ++i) {
      const glm::dvec3 d = path[i].position - path[i - 1].position;
      const double len = glm::length(d);
      EXPECT_LE(len, step + 1e-3) << "frame " << i;
      total += len;
      EXPECT_NEAR(path[i].t - path[i - 1].t, 1.0 / 30.0, 1e-9);
      if (len > 1e-6) {
        const glm::vec3 a = town().scene.toLocal(path[i - 1].position);
        const glm::vec3 b = town().scene.toLocal(path[i].position);
        EXPECT_FALSE(town().oracle->occluded(Ray{a, b - a, 0.0f, 1.0f})) << "frame " << i;
      }
    }
    // Corners shorten a few steps; on average the walker keeps its pace.
    EXPECT_GT(total, 0.9 * step * double(path.size() - 1)) << "speed " << speed;
  }
}

TEST(WalkthroughPath, TurnsTheGazeAtABoundedRateAndStaysUpright) {
  const auto path = walk(1.0, 600, 3);
  for (size_t i = 1; i < path.size(); ++i) {
    EXPECT_LE(std::abs(std::remainder(path[i].yawDeg - path[i - 1].yawDeg, 360.0)),
              120.0 / 30.0 + 1e-9);
    EXPECT_EQ(path[i].pitchDeg, 0.0);
  }
}

TEST(WalkthroughPath, IsDeterministicBySeed) {
  const auto a = walk(1.0, 100, 9), b = walk(1.0, 100, 9), c = walk(1.0, 100, 10);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].position, b[i].position);
  EXPECT_NE(a.front().position, c.front().position);
}

TEST(WalkthroughPath, RefusesOptionsOutOfRangeNamingTheOption) {
  const Town& t = town();
  auto refuses = [&](auto set, const char* word) {
    PathOptions o;
    o.frames = 10;
    set(o);
    try {
      generatePath(t.scene, t.freeSpace, o);
      ADD_FAILURE() << "accepted a bad " << word;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
    }
  };
  const double inf = std::numeric_limits<double>::infinity();
  refuses([](PathOptions& o) { o.fps = 0.0; }, "fps");
  refuses([&](PathOptions& o) { o.fps = inf; }, "fps");
  refuses([](PathOptions& o) { o.speed = -1.0; }, "speed");
  refuses([](PathOptions& o) { o.lookAhead = -1.0; }, "look-ahead");
  refuses([](PathOptions& o) { o.maxTurnDegPerS = 0.0; }, "turn rate");
  refuses([](PathOptions& o) { o.goalRadius = std::nan(""); }, "goal radius");
  refuses([&](PathOptions& o) { o.goalClearance = inf; }, "goal clearance");
  refuses([&](PathOptions& o) { o.eyeHeight = inf; }, "eye height");
}

TEST(WalkthroughPath, FallsBackToEveryWalkableColumnWhenTheGoalRuleLeavesNone) {
  // A clearance wider than the town leaves no goal column; radius and
  // clearance far beyond the grid must not overflow the window arithmetic.
  PathOptions o;
  o.frames = 60;
  o.goalClearance = 1e12;
  o.goalRadius = 1e12;
  EXPECT_EQ(goalColumns(town().freeSpace, o), town().freeSpace.walkableColumns());
  EXPECT_EQ(generatePath(town().scene, town().freeSpace, o).size(), 60u);
}

TEST(WalkthroughPath, StartsOnOneOfTheGoalColumnsItIsGiven) {
  const Town& t = town();
  const FreeSpace& fs = t.freeSpace;
  const std::vector<glm::ivec2> all = fs.walkableColumns();
  // Two far-apart columns: the walk starts on one of them.
  const std::vector<glm::ivec2> goals{all.front(), all.back()};
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    PathOptions o;
    o.frames = 5;
    o.seed = seed;
    const glm::vec3 start = t.scene.toLocal(generatePath(t.scene, fs, goals, o).front().position);
    const glm::ivec2 c = fs.columnOf(glm::vec2(start.x, start.z));
    EXPECT_TRUE(c == goals[0] || c == goals[1]) << c.x << "," << c.y;
  }
  const glm::ivec2 blocked = [&] {
    for (int k = 0; k < fs.columnsZ(); ++k)
      for (int i = 0; i < fs.columnsX(); ++i)
        if (!fs.walkable(i, k)) return glm::ivec2(i, k);
    return glm::ivec2(-1, -1);
  }();
  ASSERT_GE(blocked.x, 0);
  EXPECT_THROW(generatePath(t.scene, fs, {blocked, all.front()}, PathOptions{}), InputError);
}

TEST(ViewDirection, FollowsThePathFileConvention) {
  const glm::dvec3 ahead = viewDirection(0, 0), left = viewDirection(90, 0),
                   up = viewDirection(0, 90);
  EXPECT_NEAR(ahead.z, -1.0, 1e-12);
  EXPECT_NEAR(left.x, -1.0, 1e-12);
  EXPECT_NEAR(up.y, 1.0, 1e-12);
}

class PathFile : public ::testing::Test {
 protected:
  std::filesystem::path file = std::filesystem::temp_directory_path() /
                               ("vistream_path_" + std::to_string(::getpid()) + ".csv");
  void write(const std::string& text) { std::ofstream(file) << text; }
  void TearDown() override { std::filesystem::remove(file); }
  std::string errorOf() {
    try {
      readPath(file);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  }
};

TEST_F(PathFile, RoundTripsThroughWriteAndRead) {
  const auto path = walk(1.0, 50, 4);
  writePath(path, file);
  const auto back = readPath(file);
  ASSERT_EQ(back.size(), path.size());
  for (size_t i = 0; i < path.size(); ++i) {
    EXPECT_NEAR(back[i].t, path[i].t, 1e-6);
    EXPECT_NEAR(glm::length(back[i].position - path[i].position), 0.0, 1e-5);
    EXPECT_NEAR(back[i].yawDeg, path[i].yawDeg, 1e-4);
  }
}

TEST_F(PathFile, RejectsAWrongHeaderNamingTheLine) {
  write("\nt,x,y,z,yaw,pitch\n0,0,0,0,0,0\n");
  EXPECT_NE(errorOf().find(":2: expected the header"), std::string::npos) << errorOf();
}

TEST_F(PathFile, RejectsNonNumericAndNonFiniteFields) {
  write("t,x,y,z,yaw_deg,pitch_deg\n0,1,2,3,4,5\n0.1,1,nan,3,4,5\n");
  EXPECT_NE(errorOf().find(":3: field 3"), std::string::npos) << errorOf();
  write("t,x,y,z,yaw_deg,pitch_deg\n0,1,2,3,abc,5\n");
  EXPECT_NE(errorOf().find(":2: field 5"), std::string::npos) << errorOf();
}

TEST_F(PathFile, RejectsMissingFieldsTimeGoingBackwardsAndPitchBeyondVertical) {
  write("t,x,y,z,yaw_deg,pitch_deg\n0,1,2,3,4\n");
  EXPECT_NE(errorOf().find(":2: 5 fields"), std::string::npos) << errorOf();
  write("t,x,y,z,yaw_deg,pitch_deg\n1,1,2,3,4,5\n0.5,1,2,3,4,5\n");
  EXPECT_NE(errorOf().find(":3: t goes backwards"), std::string::npos) << errorOf();
  write("t,x,y,z,yaw_deg,pitch_deg\n0,1,2,3,4,95\n");
  EXPECT_NE(errorOf().find(":2: pitch"), std::string::npos) << errorOf();
}

TEST_F(PathFile, RejectsAnEmptyFileAndAFileWithOnlyAHeader) {
  write("");
  EXPECT_NE(errorOf().find("empty path file"), std::string::npos) << errorOf();
  write("t,x,y,z,yaw_deg,pitch_deg\n");
  EXPECT_NE(errorOf().find("no samples"), std::string::npos) << errorOf();
}

}  // namespace
}  // namespace vistream
