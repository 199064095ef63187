// PanoramicCache::invalidate against brute force: texels are stored from
// known rays (random directions inside their texels, from eyes within the
// record spacing), triangles are added and removed, and every texel the cache
// keeps must still be right: its ray, cast again by the brute-force oracle
// over the changed scene, hits the same triangle at the same distance. Known
// answers: geometry hidden behind every recorded hit keeps every texel;
// geometry in front of some forgets those.
#include <gtest/gtest.h>

#include <map>
#include <memory>
#include <random>

#include "client/farfield/image_cache.h"
#include "common/raycast/ray_query.h"
#include "tests/common/support/triangle_soups.h"

namespace vistream {
namespace {

using testing::Triangle;

void addBox(std::vector<Triangle>& out, glm::vec3 lo, glm::vec3 hi) {
  const std::vector<Triangle> box = testing::boxTriangles(lo, hi);
  out.insert(out.end(), box.begin(), box.end());
}

Box3f boundsOf(const std::vector<Triangle>& triangles, size_t first) {
  Box3f b;
  for (size_t t = first; t < triangles.size(); ++t)
    for (const glm::vec3& p : triangles[t]) b.extend(p);
  return b;
}

// A cache filled from rays it remembers, over a scene that changes.
struct CacheUnderTest {
  std::vector<Triangle> scene;
  std::vector<uint8_t> removed;  // per triangle
  PanoramicCache cache{0.01f};
  std::map<int64_t, Ray> rayOf;  // the ray each texel's colour came from

  std::unique_ptr<RayQuery> oracle(FlatTriangles& storage) const {
    storage = testing::makeTriangles(scene);
    for (size_t i = 0; i < removed.size(); ++i)
      if (removed[i]) storage.degenerate[i] = 1;
    return makeBruteForceRayQuery(storage);
  }
  // Traces `n` random rays from within a few millimetres of `eye`.
  void fill(glm::vec3 eye, size_t n, std::mt19937& rng) {
    std::vector<uint8_t> trace;
    (void)cache.plan(eye, {}, 0, 1.0f, trace);  // opens the record at eye
    FlatTriangles t = testing::makeTriangles(scene);
    const auto oracle = makeBruteForceRayQuery(t);
    std::uniform_real_distribution<float> jitter(-0.004f, 0.004f);
    for (size_t i = 0; i < n; ++i) {
      const glm::vec3 dir = testing::randomDirection(rng);
      const int64_t texel = cache.texelOf(dir);
      if (texel < 0) continue;
      const Ray ray{eye + glm::vec3(jitter(rng), jitter(rng), jitter(rng)), dir};
      const Hit hit = oracle->firstHit(ray);
      cache.store(texel, glm::u8vec3(hit.valid() ? 200 : 0),
                  hit.valid() ? hit.t : std::numeric_limits<float>::infinity(),
                  hit.valid() ? hit.triangle : PanoramicCache::kNoTexelHit);
      rayOf[texel] = ray;
    }
  }
  size_t traced() const {
    size_t n = 0;
    for (const auto& [texel, ray] : rayOf) n += cache.traced(texel);
    return n;
  }
  // Every texel still traced sees what it saw: the oracle agrees.
  void expectKeptTexelsUnchanged(const std::vector<Triangle>& before,
                                 const std::vector<uint8_t>& removedBefore) const {
    CacheUnderTest old;
    old.scene = before;
    old.removed = removedBefore;
    FlatTriangles thenStorage, nowStorage;
    const auto thenQuery = old.oracle(thenStorage), nowQuery = oracle(nowStorage);
    size_t checked = 0;
    for (const auto& [texel, ray] : rayOf) {
      if (!cache.traced(texel)) continue;
      const Hit then = thenQuery->firstHit(ray), now = nowQuery->firstHit(ray);
      ASSERT_EQ(now.triangle, then.triangle) << "texel " << texel;
      ASSERT_EQ(now.t, then.t) << "texel " << texel;
      ++checked;
    }
    EXPECT_GT(checked, 0u);
  }
};

TEST(CacheInvalidation, KeepsEveryTexelWhenTheNewGeometryLiesBehindEveryHit) {
  std::mt19937 rng(1);
  CacheUnderTest c;
  addBox(c.scene, {-10, -3, -10}, {10, 12, 10});  // a closed room around the eye
  c.fill({0, 1.7f, 0}, 20'000, rng);
  const size_t traced = c.traced();
  ASSERT_GT(traced, 5'000u);
  const size_t first = c.scene.size();
  addBox(c.scene, {40, 0, -5}, {50, 20, 5});  // outside the room
  const Box3f added = boundsOf(c.scene, first);
  EXPECT_EQ(c.cache.invalidate({&added, 1}, {}), 0u);
  EXPECT_EQ(c.traced(), traced);
}

TEST(CacheInvalidation, ForgetsTexelsTheNewGeometryMayCoverAndKeepsTheRestRight) {
  std::mt19937 rng(2);
  CacheUnderTest c;
  addBox(c.scene, {-30, -3, -30}, {30, 12, 30});
  c.fill({0, 1.7f, 0}, 20'000, rng);
  const std::vector<Triangle> before = c.scene;
  const size_t traced = c.traced();
  const size_t first = c.scene.size();
  addBox(c.scene, {-2, 0, -12}, {2, 4, -8});  // in front of the far wall, along -Z
  const Box3f added = boundsOf(c.scene, first);
  const size_t forgotten = c.cache.invalidate({&added, 1}, {});
  EXPECT_GT(forgotten, 0u);
  EXPECT_LT(forgotten, traced / 4) << "texels looking elsewhere stay";
  c.removed.assign(c.scene.size(), 0);
  c.expectKeptTexelsUnchanged(before, std::vector<uint8_t>(before.size(), 0));
}

TEST(CacheInvalidation, ForgetsExactlyTheTexelsThatHitARemovedTriangle) {
  std::mt19937 rng(3);
  CacheUnderTest c;
  addBox(c.scene, {-30, -3, -30}, {30, 12, 30});
  addBox(c.scene, {-2, 0, -12}, {2, 4, -8});
  c.fill({0, 1.7f, 0}, 20'000, rng);
  const std::vector<Triangle> before = c.scene;
  // Which texels saw the small box (triangles 12..23), by the oracle.
  size_t sawBox = 0;
  FlatTriangles storage;
  const auto query = c.oracle(storage);
  for (const auto& [texel, ray] : c.rayOf) {
    const Hit h = query->firstHit(ray);
    sawBox += c.cache.traced(texel) && h.valid() && h.triangle >= 12;
  }
  ASSERT_GT(sawBox, 0u);
  std::vector<uint8_t> removed(c.scene.size(), 0);
  for (size_t t = 12; t < 24; ++t) removed[t] = 1;
  EXPECT_EQ(c.cache.invalidate({}, removed), sawBox);
  c.removed = removed;
  // Kept texels saw the room's walls, which are still there.
  c.expectKeptTexelsUnchanged(before, std::vector<uint8_t>(before.size(), 0));
}

TEST(CacheInvalidation, ForgetsExactlyTheTexelsThatShowedAnImpostorWhenTheImpostorsChange) {
  std::mt19937 rng(4);
  CacheUnderTest c;
  addBox(c.scene, {-30, -3, -30}, {30, 12, 30});
  c.fill({0, 1.7f, 0}, 20'000, rng);
  // Texels looking up (slope above 1) show an impostor's point 20 m away
  // instead of the ceiling: what the pipeline stores where a point won.
  size_t impostorTexels = 0;
  for (const auto& [texel, ray] : c.rayOf)
    if (c.cache.traced(texel) && ray.dir.y > glm::length(glm::vec2(ray.dir.x, ray.dir.z))) {
      c.cache.store(texel, glm::u8vec3(90), 20.0f, PanoramicCache::kImpostorTexelHit);
      ++impostorTexels;
    }
  ASSERT_GT(impostorTexels, 100u);
  const size_t traced = c.traced();
  // The same geometry and impostors: nothing to forget.
  EXPECT_EQ(c.cache.invalidate({}, {}), 0u);
  EXPECT_EQ(c.traced(), traced);
  // The impostors changed: exactly the impostor texels go.
  EXPECT_EQ(c.cache.invalidate({}, {}, true), impostorTexels);
  EXPECT_EQ(c.traced(), traced - impostorTexels);
  size_t stillImpostor = 0;
  for (const auto& [texel, ray] : c.rayOf)
    stillImpostor += c.cache.traced(texel) && c.cache.showsImpostor(texel);
  EXPECT_EQ(stillImpostor, 0u);
  // What is left saw the room's walls, which are still there.
  c.expectKeptTexelsUnchanged(c.scene, std::vector<uint8_t>(c.scene.size(), 0));
}

}  // namespace
}  // namespace vistream
