#include "common/world/solids.h"

#include <gtest/gtest.h>

#include "tests/common/world/wound_boxes.h"

namespace vistream {
namespace {

using testing::addWoundBox;
using testing::Winding;

struct Built {
  Scene scene;
  FlatTriangles triangles;
  std::unique_ptr<RayQuery> rays;
  Solids solids;
  void build() {
    finalizeScene(scene);
    triangles = flattenScene(scene);
    rays = makeEmbreeRayQuery(triangles);
    solids = Solids::build(triangles);
  }
  size_t count(SolidClass c) const { return solids.census().components[size_t(c)]; }
  bool inside(glm::vec3 p) const { return solids.inside(*rays, p); }
};

TEST(Solids, AClosedCubeIsOutwardOrInwardBySignedVolume) {
  for (const Winding w : {Winding::Outward, Winding::Inward}) {
    Built b;
    addWoundBox(b.scene, "cube", {0, 0, 0}, {2, 3, 4}, w);
    b.build();
    ASSERT_EQ(b.solids.components().size(), 1u);
    const SolidComponent& c = b.solids.components()[0];
    EXPECT_EQ(c.kind, w == Winding::Outward ? SolidClass::ClosedOutward : SolidClass::ClosedInward);
    EXPECT_NEAR(std::abs(c.signedVolume), 24.0, 1e-4);  // 2 x 3 x 4
    EXPECT_EQ(c.faces, 6u);
    EXPECT_EQ(c.triangles, 12u);
  }
}

TEST(Solids, ABoxWithoutItsBottomIsOpenAndOneFlippedFaceMakesACubeInconsistent) {
  Built open;
  addWoundBox(open.scene, "wall", {0, 0, 0}, {4, 3, 0.2f}, Winding::Outward, /*bottom=*/false);
  open.build();
  EXPECT_EQ(open.count(SolidClass::Open), 1u);

  Built mixed;
  addWoundBox(mixed.scene, "cube", {0, 0, 0}, {2, 2, 2}, Winding::SidesInward);
  mixed.build();
  EXPECT_EQ(mixed.count(SolidClass::Inconsistent), 1u);
  EXPECT_EQ(mixed.solids.census().faces[size_t(SolidClass::Inconsistent)], 6u);
}

TEST(Solids, PointsInsideClosedOutwardOpenAndInconsistentMeshesAreInsideWhateverTheWinding) {
  for (const Winding w : {Winding::Outward, Winding::SidesInward}) {
    for (const bool bottom : {true, false}) {
      Built b;
      addWoundBox(b.scene, "block", {0, 0, 0}, {10, 6, 10}, w, bottom);
      b.build();
      EXPECT_TRUE(b.inside({5, 1, 5})) << int(w) << bottom;
      EXPECT_TRUE(b.inside({0.3f, 1, 9.6f})) << int(w) << bottom;  // near a corner
      EXPECT_FALSE(b.inside({-1, 1, 5})) << int(w) << bottom;
      EXPECT_FALSE(b.inside({5, 7, 5})) << int(w) << bottom;
      EXPECT_FALSE(b.inside({5, 6, 5})) << "on the roof counts as outside";
    }
  }
}

TEST(Solids, AClosedInwardCubeIsTheSameSolidAsAnOutwardOne) {
  Built b;
  addWoundBox(b.scene, "cube", {0, 0, 0}, {10, 3, 10}, Winding::Inward);
  b.build();
  EXPECT_EQ(b.count(SolidClass::ClosedInward), 1u);
  EXPECT_TRUE(b.inside({5, 1, 5}));
  EXPECT_TRUE(b.inside({9.9f, 2.9f, 0.1f}));
  EXPECT_FALSE(b.inside({-5, 1, 5}));
  EXPECT_FALSE(b.inside({5, 3.5f, 5}));
}

TEST(Solids, TwoCubesSharingAFaceAreBothSolidAndTheirSharedEdgesNonManifold) {
  Built b;
  testing::addBox(b.scene, "a", {-2, 0, -1}, {0, 3, 1});
  testing::addBox(b.scene, "b", {0, 0, -1}, {2, 3, 1});
  b.build();
  EXPECT_GT(b.count(SolidClass::NonManifold), 0u);
  EXPECT_EQ(b.count(SolidClass::ClosedOutward), 0u);
  EXPECT_TRUE(b.inside({-1, 1.5f, 0}));
  EXPECT_TRUE(b.inside({1, 1.5f, 0}));
  EXPECT_TRUE(b.inside({-0.1f, 1.5f, 0.2f}));  // beside the shared face
  EXPECT_FALSE(b.inside({0, 1.5f, 2}));
  EXPECT_FALSE(b.inside({3, 1.5f, 0}));
  EXPECT_FALSE(b.inside({0, 3.5f, 0}));
}

TEST(Solids, TwoBoxesMeetingAtANonManifoldEdgeStayTwoSolidsWithAnEmptyNotch) {
  Built b;
  testing::addBox(b.scene, "a", {-2, 0, -2}, {0, 3, 0});
  testing::addBox(b.scene, "b", {0, 0, 0}, {2, 3, 2});
  b.build();
  ASSERT_EQ(b.solids.components().size(), 2u);
  EXPECT_EQ(b.count(SolidClass::NonManifold), 2u);
  EXPECT_TRUE(b.inside({-1, 1.5f, -1}));
  EXPECT_TRUE(b.inside({1, 1.5f, 1}));
  EXPECT_FALSE(b.inside({-1, 1.5f, 1}));  // the two notches beside the shared edge
  EXPECT_FALSE(b.inside({1, 1.5f, -1}));
}

TEST(Solids, ASheetBelowOrAboveAPointDoesNotContainIt) {
  Built b;
  testing::addGround(b.scene, -10, -10, 10, 10);
  testing::addGround(b.scene, -10, -10, 10, 10, 3.0f);  // a ceiling sheet, wound up
  b.build();
  EXPECT_EQ(b.count(SolidClass::Open), 2u);
  EXPECT_FALSE(b.inside({0, 1, 0}));
}

}  // namespace
}  // namespace vistream
