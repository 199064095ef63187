// FrameRenderer::update against renderers built from scratch: after any
// sequence of faces added, evicted and sent again (a StreamedGeometry taking
// up GeometryDeltas), the updated renderer draws, pixel for pixel, what a
// renderer built over the live triangles draws (cache off, same grid cell),
// and with the image cache on it stays within the pipeline's tolerance of
// the ray-cast reference (no pixel wrong inside a uniform patch), keeping
// the cached pixels the change cannot touch.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>

#include "client/app/walkthrough.h"
#include "client/farfield/pipeline.h"
#include "client/render/streamed_geometry.h"
#include "tests/common/support/camera_at.h"
#include "tests/common/support/triangle_soups.h"

namespace vistream {
namespace {

// A street of box buildings along -Z: box 0 is the ground, then a building on
// each side every 25 m. Each box has 6 faces (IDs 6 * box + side) of 2 triangles.
std::vector<std::pair<glm::vec3, glm::vec3>> streetBoxes(float length) {
  std::vector<std::pair<glm::vec3, glm::vec3>> boxes = {
      {{-200.0f, -1.0f, -length - 200.0f}, {200.0f, 0.0f, 200.0f}}};
  for (float z = 0.0f; z > -length; z -= 25.0f) {
    const float h = 10.0f + std::fmod(std::abs(z) * 0.37f, 30.0f);
    boxes.push_back({{-30.0f, 0.0f, z - 20.0f}, {-8.0f, h, z}});
    boxes.push_back({{8.0f, 0.0f, z - 20.0f}, {30.0f, h * 0.8f + 5.0f, z}});
  }
  return boxes;
}

// The faces of the chosen boxes as a delta's `added` (coloured per box).
RenderGeometry facesOf(const std::vector<std::pair<glm::vec3, glm::vec3>>& boxes,
                       const std::vector<size_t>& chosen) {
  RenderGeometry g;
  std::vector<size_t> boxOf;
  for (const size_t b : chosen) {
    const std::vector<testing::Triangle> box =
        testing::boxTriangles(boxes[b].first, boxes[b].second);
    for (size_t t = 0; t < box.size(); ++t) {
      g.triangles.positions.insert(g.triangles.positions.end(), box[t].begin(), box[t].end());
      g.triangles.faceIds.push_back(uint32_t(6 * b + t / 2));
      g.triangles.objectIds.push_back(0);
      g.triangles.degenerate.push_back(0);
      boxOf.push_back(b);
    }
  }
  recolour(g, [&](size_t t) {
    const float h = float(boxOf[t] % 7) / 7.0f;
    return glm::vec3(0.3f + 0.6f * h, 0.8f - 0.5f * h, 0.5f);
  });
  return g;
}

// Every face ID of the chosen boxes.
std::vector<uint32_t> faceIdsOf(const std::vector<size_t>& chosen) {
  std::vector<uint32_t> ids;
  for (const size_t b : chosen)
    for (uint32_t side = 0; side < 6; ++side) ids.push_back(uint32_t(6 * b) + side);
  return ids;
}

Camera smallCameraAt(glm::vec3 eye, float yaw, float pitch = 0.0f) {
  return testing::cameraAt(eye, yaw, pitch, 240, 180);
}

PipelineOptions splitAt(float d, bool cache) {
  PipelineOptions o;
  o.polygonBudget = 0;
  o.nearDistance = d;
  o.horizonCellSize = 4.0f;
  o.gridCellSize = 8.0f;  // the same cells from scratch and updated
  o.cache = cache;
  return o;
}

ImageRgb8 renderFromScratch(const RenderGeometry& g, PipelineOptions o, const Camera& c) {
  FrameRenderer r(g, o);
  ImageRgb8 image;
  r.render(c, image);
  return image;
}

TEST(IncrementalPipeline, DrawsWhatARendererBuiltFromScratchDrawsAfterAnyAddsAndEvicts) {
  const auto boxes = streetBoxes(800.0f);
  std::mt19937 rng(5);
  StreamedGeometry streamed;
  std::set<size_t> held;
  std::unique_ptr<FrameRenderer> pipeline, raycast;
  const std::vector<Camera> cameras = {smallCameraAt({0.0f, 1.7f, -5.0f}, 0.0f),
                                       smallCameraAt({0.0f, 1.7f, -120.0f}, 20.0f, 5.0f),
                                       smallCameraAt({3.0f, 30.0f, -60.0f}, 180.0f, -10.0f)};
  size_t farFieldFrames = 0;  // frames whose far field hit something
  for (int step = 0; step < 12; ++step) {
    SCOPED_TRACE(::testing::Message() << "step " << step);
    GeometryDelta delta;
    // Add up to 8 boxes not held (the ground first), evict up to 4 held, send 2 held again.
    std::vector<size_t> add, again;
    if (step == 0) add.push_back(0);
    std::uniform_int_distribution<size_t> anyBox(1, boxes.size() - 1);
    for (int k = 0; k < 8; ++k)
      if (const size_t b = anyBox(rng);
          !held.count(b) && std::find(add.begin(), add.end(), b) == add.end())
        add.push_back(b);
    std::vector<size_t> heldList(held.begin(), held.end());
    std::shuffle(heldList.begin(), heldList.end(), rng);
    std::vector<size_t> evict(heldList.begin(),
                              heldList.begin() + std::min<size_t>(heldList.size(), 4));
    if (heldList.size() > 6) again = {heldList[4], heldList[5]};
    delta.removed = faceIdsOf(evict);
    std::vector<size_t> sent = add;
    sent.insert(sent.end(), again.begin(), again.end());
    delta.added = facesOf(boxes, sent);
    for (const size_t b : evict) held.erase(b);
    held.insert(add.begin(), add.end());

    const GeometryChange change = streamed.apply(delta);
    if (!pipeline) {
      pipeline = std::make_unique<FrameRenderer>(streamed.geometry(), splitAt(60.0f, false));
      PipelineOptions r = splitAt(60.0f, false);
      r.mode = RenderMode::RaycastAll;
      raycast = std::make_unique<FrameRenderer>(streamed.geometry(), r);
    } else {
      ASSERT_TRUE(pipeline->update(change));
      ASSERT_TRUE(raycast->update(change));
    }
    EXPECT_EQ(streamed.faces(), 6 * held.size());
    const RenderGeometry scratch = streamed.compacted();
    ASSERT_EQ(scratch.size(), 12 * held.size());
    for (size_t ci = 0; ci < cameras.size(); ++ci) {
      SCOPED_TRACE(::testing::Message() << "camera " << ci);
      ImageRgb8 image;
      const FrameReport report = pipeline->render(cameras[ci], image);
      const ImageRgb8 expected = renderFromScratch(scratch, splitAt(60.0f, false), cameras[ci]);
      EXPECT_EQ(image.pixels, expected.pixels);
      if (step == 0) continue;  // the ground alone: no far field to compare
      PipelineOptions r = splitAt(60.0f, false);
      r.mode = RenderMode::RaycastAll;
      raycast->render(cameras[ci], image);
      EXPECT_EQ(image.pixels, renderFromScratch(scratch, r, cameras[ci]).pixels);
      farFieldFrames += report.pixels.rayHit > 0;
    }
  }
  EXPECT_GT(farFieldFrames, 5u) << "the far field took part";
}

TEST(IncrementalPipeline, TheCacheKeepsWhatNewFacesCannotChangeAndTheFrameStaysRight) {
  const auto boxes = streetBoxes(1500.0f);
  StreamedGeometry streamed;
  // The ground and the first 300 m of the street.
  std::vector<size_t> nearBoxes, farBoxes;
  for (size_t b = 0; b < boxes.size(); ++b)
    (b == 0 || boxes[b].second.z > -300.0f ? nearBoxes : farBoxes).push_back(b);
  GeometryDelta first;
  first.added = facesOf(boxes, nearBoxes);
  streamed.apply(first);
  PipelineOptions o = splitAt(60.0f, true);
  o.pixelBudget = 0;  // only pixels the cache must refresh are traced
  FrameRenderer renderer(streamed.geometry(), o);
  ImageRgb8 image;
  auto expectRight = [&](const Camera& c) {
    const FrameReport report = renderer.render(c, image);
    PipelineOptions r = o;
    r.mode = RenderMode::RaycastAll;
    const ImageDifference diff =
        compareImages(image, renderFromScratch(streamed.compacted(), r, c));
    EXPECT_EQ(diff.interiorDiffering, 0u) << "holes or stale pixels";
    EXPECT_LT(diff.differingFraction, 0.005);
    return report;
  };
  for (int i = 0; i < 4; ++i)
    expectRight(smallCameraAt({0.0f, 1.7f, -5.0f - 0.002f * float(i)}, 0.0f));
  const Camera still = smallCameraAt({0.0f, 1.7f, -5.01f}, 0.0f);
  const FrameReport before = expectRight(still);
  ASSERT_GT(before.pixels.cache, 1000u);

  // The rest of the street arrives: it shows down the street, past the near
  // buildings, whose cached pixels stay.
  GeometryDelta far;
  far.added = facesOf(boxes, farBoxes);
  ASSERT_TRUE(renderer.update(streamed.apply(far)));
  EXPECT_GT(renderer.lastUpdate().texelsForgotten, 0u);
  const FrameReport afterAdd = expectRight(still);
  EXPECT_GT(afterAdd.pixels.cache, before.pixels.cache / 2) << "most cached pixels kept";
  EXPECT_GT(afterAdd.pixels.rayHit, 0u) << "the new buildings are traced";

  // Buildings 80-150 m away on the right are evicted: the pixels that saw them are retraced.
  std::vector<size_t> gone;
  for (const size_t b : nearBoxes)
    if (b != 0 && boxes[b].first.x > 0 && boxes[b].second.z < -80.0f && boxes[b].second.z > -150.0f)
      gone.push_back(b);
  ASSERT_FALSE(gone.empty());
  GeometryDelta evict;
  evict.removed = faceIdsOf(gone);
  ASSERT_TRUE(renderer.update(streamed.apply(evict)));
  EXPECT_GT(renderer.lastUpdate().texelsForgotten, 0u);
  const FrameReport afterEvict = expectRight(still);
  EXPECT_GT(afterEvict.pixels.cache, 0u);
}

}  // namespace
}  // namespace vistream
