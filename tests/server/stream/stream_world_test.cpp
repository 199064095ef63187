// StreamWorld's ground decision, which every client's Welcome carries, and
// the nesting of its face sets (unculled, coarse, the cell's own) against
// brute force and the PVS computed directly.
#include "server/stream/stream_world.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <future>

#include "tests/common/support/box_scenes.h"
#include "tests/server/stream/stream_test_support.h"

namespace vistream {
namespace {

// A district of box buildings with bases at known heights and nothing
// between them, like a LoD2 city model.
Scene buildingsOnly(bool withGround) {
  Scene scene;
  scene.name = withGround ? "district with ground" : "district";
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      const float x = float(i) * 40.0f, z = float(k) * 40.0f;
      const float base = 2.0f - 0.75f * float(i + k);  // the lowest is -1 m (i = k = 2)
      testing::addBox(scene, "b", {x, base, z}, {x + 20.0f, 15.0f, z + 20.0f});
    }
  if (withGround) testing::addGround(scene, -10.0f, -10.0f, 110.0f, 110.0f, -1.0f);
  finalizeScene(scene);
  return scene;
}

TEST(StreamWorld, AssumesAGroundPlaneAtTheLowestBaseOfAModelWithoutOne) {
  StreamWorldOptions options;
  options.cellSize = 8.0f;
  const StreamWorld world(buildingsOnly(false), options);
  ASSERT_TRUE(world.ground().y.has_value()) << world.ground().why;
  EXPECT_FLOAT_EQ(float(world.scene().toFile(glm::vec3(0.0f, *world.ground().y, 0.0f)).y), -1.0f);
}

TEST(StreamWorld, KeepsTheScenesOwnGroundAndHonoursGroundNone) {
  StreamWorldOptions options;
  options.cellSize = 8.0f;
  EXPECT_FALSE(StreamWorld(buildingsOnly(true), options).ground().y.has_value());
  options.ground.mode = GroundMode::None;
  EXPECT_FALSE(StreamWorld(buildingsOnly(false), options).ground().y.has_value());
}

// The unculled set of a cell is every face whose bounding box lies within
// the radius of the cell's 2 x 1 x 2 block (the oracle: every face of the
// scene, measured by hand), and it contains the coarse set, which contains
// the cell's own, which contains the cell's PVS computed directly by
// EpsilonPvs within the radius: a client holding a looser set never lacks a
// face of a tighter one.
TEST(StreamWorld, EachFaceSetLevelContainsTheTighterOnesAndTheUnculledOneIsEveryFaceNearTheBlock) {
  StreamWorld world(testing::streetScene(), StreamWorldOptions{});
  const EpsilonPvs direct(world.scene());
  boost::asio::thread_pool pool(2);
  constexpr float kRadius = 15.0f;  // small: the levels' different reach shows
  const Scene& scene = world.scene();
  std::vector<Box3f> faceBoxes(scene.faceCount);
  for (const Object& o : scene.objects)
    for (size_t t = 0; t < o.mesh.triangles.size(); ++t)
      for (int k = 0; k < 3; ++k)
        faceBoxes[o.mesh.faceIds[t]].extend(o.mesh.positions[o.mesh.triangles[t][k]]);
  auto within = [&](const Box3f& box) {
    FaceList out;
    for (uint32_t f = 0; f < scene.faceCount; ++f) {
      const glm::vec3 gap =
          glm::max(glm::vec3(0.0f), glm::max(faceBoxes[f].lo - box.hi, box.lo - faceBoxes[f].hi));
      if (glm::length(gap) <= kRadius) out.push_back(f);
    }
    return out;
  };
  auto faceSet = [&](const glm::ivec3& cell, CellLevel level) {
    std::promise<FaceListPtr> p;
    world.cellFaceSet(
        cell, level, StreamPolicy::Visibility, kRadius, pool,
        [&](FaceListPtr f) { p.set_value(f); }, CellWork{});
    return p.get_future().get();
  };
  auto contains = [](const FaceList& a, const FaceList& b) {
    return std::includes(a.begin(), a.end(), b.begin(), b.end());
  };
  const ViewCellGrid& grid = world.grid();
  size_t cells = 0, unculledLarger = 0;
  for (int z = 0; z < grid.dims().z; z += 3)
    for (int x = 0; x < grid.dims().x; x += 3) {
      const glm::ivec3 cell(x, 0, z);
      SCOPED_TRACE(::testing::Message() << "cell " << x << ", " << z);
      Box3f block;
      for (int dz = 0; dz <= 1; ++dz)
        for (int dx = 0; dx <= 1; ++dx) {
          const glm::ivec3 member((x & ~1) + dx, 0, (z & ~1) + dz);
          if (grid.contains(member)) block.extend(grid.cellBox(member));
        }
      const Box3f box = grid.cellBox(cell);
      FaceList oracle;
      const FaceList pvs = direct.compute(box).faces, near = within(box);
      std::set_intersection(pvs.begin(), pvs.end(), near.begin(), near.end(),
                            std::back_inserter(oracle));
      const FaceListPtr unculled = faceSet(cell, CellLevel::Unculled);
      const FaceListPtr coarse = faceSet(cell, CellLevel::Coarse);
      const FaceListPtr fine = faceSet(cell, CellLevel::Fine);
      ASSERT_TRUE(unculled && coarse && fine);
      EXPECT_EQ(*unculled, within(block));
      EXPECT_TRUE(
          world.hasCellFaceSet(cell, CellLevel::Unculled, StreamPolicy::Visibility, kRadius));
      EXPECT_TRUE(contains(*unculled, *coarse));
      EXPECT_TRUE(contains(*coarse, *fine));
      EXPECT_TRUE(contains(*fine, oracle));
      unculledLarger += unculled->size() > coarse->size();
      ++cells;
    }
  EXPECT_GT(cells, 4u);
  EXPECT_GT(unculledLarger, 0u) << "somewhere visibility culls, so refining matters";
}

// Every cell of a block asks for the same unculled set: it is computed once
// and shared, however many clients ask at once, and it is not a PVS.
TEST(StreamWorld, TheCellsOfOneBlockShareOneUnculledSetComputedOnce) {
  StreamWorld world(testing::streetScene(), StreamWorldOptions{});
  boost::asio::thread_pool pool(2);
  const glm::ivec3 first(4, 0, 6);  // even: the block's first cell
  std::vector<std::promise<FaceListPtr>> answers(40);
  for (size_t i = 0; i < answers.size(); ++i) {
    const glm::ivec3 member = first + glm::ivec3(int(i % 2), 0, int(i / 2 % 2));
    world.cellFaceSet(
        member, CellLevel::Unculled, StreamPolicy::Visibility, 20.0f, pool,
        [&answers, i](FaceListPtr f) { answers[i].set_value(f); },
        CellWork{{WorkPriority::Immediate, 0.0}, nullptr, {}});
  }
  FaceListPtr shared;
  for (auto& a : answers) {
    const FaceListPtr f = a.get_future().get();
    ASSERT_TRUE(f);
    if (!shared) shared = f;
    EXPECT_EQ(*f, *shared);
  }
  const StreamWorld::CacheStats stats = world.cacheStats();
  EXPECT_EQ(stats.unculled, 1u);
  EXPECT_EQ(stats.pvsComputed, 0u);
}

}  // namespace
}  // namespace vistream
