// The batched Embree back end against scenes built from scratch: after any
// sequence of batches added and triangles removed, every ray gets the hits a
// fresh build over the triangles still held gives (face, triangle and t
// exactly), and the brute-force oracle's (within float precision).
#include <gtest/gtest.h>

#include <random>

#include "common/raycast/embree_ray_query.h"
#include "common/raycast/ray_query.h"
#include "tests/common/support/triangle_soups.h"

namespace vistream {
namespace {

using testing::makeTriangles;
using testing::randomDirection;
using testing::Triangle;

// Random triangles in a 20 m cube, some of them on a shared integer grid so
// rays meet shared edges and equal distances (ties), a few degenerate.
std::vector<Triangle> randomSoup(std::mt19937& rng, size_t n) {
  std::uniform_real_distribution<float> pos(-10.0f, 10.0f), size(0.2f, 3.0f);
  std::uniform_int_distribution<int> cell(-8, 8);
  std::vector<Triangle> out;
  for (size_t i = 0; i < n; ++i) {
    if (i % 5 == 0) {  // two triangles of one axis-aligned integer square: a shared edge
      const glm::vec3 a(float(cell(rng)), float(cell(rng)), float(cell(rng)));
      out.push_back({a, a + glm::vec3(1, 0, 0), a + glm::vec3(1, 1, 0)});
      out.push_back({a, a + glm::vec3(1, 1, 0), a + glm::vec3(0, 1, 0)});
      ++i;
    } else if (i % 23 == 0) {
      const glm::vec3 a(pos(rng), pos(rng), pos(rng));
      out.push_back({a, a, a + glm::vec3(1.0f)});  // degenerate
    } else {
      const glm::vec3 a(pos(rng), pos(rng), pos(rng));
      out.push_back(
          {a, a + size(rng) * randomDirection(rng), a + size(rng) * randomDirection(rng)});
    }
  }
  return out;
}

// The triangles still held, at their own indices: removed ones (and those
// never added) are flagged degenerate, which every back end leaves out.
FlatTriangles heldOnly(const FlatTriangles& all, const std::vector<uint8_t>& held) {
  FlatTriangles t = all;
  for (size_t i = 0; i < t.size(); ++i)
    if (!held[i]) t.degenerate[i] = 1;
  return t;
}

std::vector<Ray> randomRays(std::mt19937& rng, size_t n) {
  std::uniform_real_distribution<float> pos(-12.0f, 12.0f);
  std::vector<Ray> rays;
  for (size_t i = 0; i < n; ++i) {
    Ray r{{pos(rng), pos(rng), pos(rng)}, randomDirection(rng)};
    if (i % 7 == 0) r.dir = glm::vec3(0.0f, 0.0f, r.dir.z < 0 ? -1.0f : 1.0f);  // axis-parallel
    if (i % 11 == 0) r.org = glm::floor(r.org) + 0.5f;  // through the integer squares' centres
    rays.push_back(r);
  }
  return rays;
}

void expectSameAnswers(const RayQuery& batched, const FlatTriangles& held, std::mt19937& rng) {
  const auto fresh = makeEmbreeRayQuery(held);
  const auto brute = makeBruteForceRayQuery(held);
  const std::vector<Ray> rays = randomRays(rng, 400);
  std::vector<Hit> batchHits(rays.size()), freshHits(rays.size());
  batched.firstHits(rays, batchHits);
  fresh->firstHits(rays, freshHits);
  std::vector<Hit> all, allFresh;
  for (size_t i = 0; i < rays.size(); ++i) {
    SCOPED_TRACE(::testing::Message() << "ray " << i);
    const Hit single = batched.firstHit(rays[i]);
    EXPECT_EQ(single.triangle, freshHits[i].triangle);
    EXPECT_EQ(batchHits[i].triangle, freshHits[i].triangle);
    if (freshHits[i].valid()) {
      EXPECT_EQ(batchHits[i].t, freshHits[i].t);
      EXPECT_EQ(held.faceIds[batchHits[i].triangle], held.faceIds[freshHits[i].triangle]);
    }
    const Hit oracle = brute->firstHit(rays[i]);
    EXPECT_EQ(batchHits[i].valid(), oracle.valid());
    if (oracle.valid() && batchHits[i].valid()) {
      EXPECT_NEAR(batchHits[i].t, oracle.t, 1e-4f * (1.0f + oracle.t));
    }
    EXPECT_EQ(batched.occluded(rays[i]), fresh->occluded(rays[i]));
    batched.allHits(rays[i], all);
    fresh->allHits(rays[i], allFresh);
    ASSERT_EQ(all.size(), allFresh.size());
    for (size_t k = 0; k < all.size(); ++k) {
      EXPECT_EQ(all[k].triangle, allFresh[k].triangle);
      EXPECT_EQ(all[k].t, allFresh[k].t);
    }
  }
}

TEST(BatchedEmbreeRayQuery, AnswersAsAFreshBuildAfterEveryAddAndRemove) {
  std::mt19937 rng(7);
  const FlatTriangles all = makeTriangles(randomSoup(rng, 1200));
  const auto query = makeBatchedEmbreeRayQuery();
  std::vector<uint8_t> held(all.size(), 0);
  std::uniform_int_distribution<uint32_t> batchSize(1, 150);
  uint32_t next = 0;
  int step = 0;
  while (next < all.size()) {
    SCOPED_TRACE(::testing::Message() << "step " << step++);
    // Add a batch.
    const uint32_t count = std::min<uint32_t>(batchSize(rng), uint32_t(all.size()) - next);
    query->addBatch(all, next, count);
    for (uint32_t t = next; t < next + count; ++t) held[t] = 1;
    next += count;
    // Remove a few triangles held (some twice, some never added: ignored),
    // now and then a whole batch's worth.
    std::vector<uint32_t> removed;
    std::uniform_int_distribution<uint32_t> any(0, uint32_t(all.size()) - 1);
    const size_t removals = step % 4 == 0 ? 60 : 8;
    for (size_t k = 0; k < removals; ++k) removed.push_back(any(rng) % std::max(next, 1u));
    removed.push_back(removed.front());
    if (next < all.size()) removed.push_back(next);  // not added yet
    query->removeTriangles(removed);
    for (const uint32_t t : removed)
      if (t < next) held[t] = 0;
    query->commit();
    expectSameAnswers(*query, heldOnly(all, held), rng);
    if (::testing::Test::HasFailure()) return;
  }
}

TEST(BatchedEmbreeRayQuery, ABatchRemovedWholeLeavesNothingOfItToHit) {
  // Two walls facing the ray; the near one's batch removed entirely.
  const FlatTriangles walls = makeTriangles({
      {glm::vec3(-1, -1, -2), glm::vec3(1, -1, -2), glm::vec3(0, 1, -2)},
      {glm::vec3(-1, -1, -5), glm::vec3(1, -1, -5), glm::vec3(0, 1, -5)},
  });
  const auto query = makeBatchedEmbreeRayQuery();
  query->addBatch(walls, 0, 1);
  query->addBatch(walls, 1, 1);
  query->commit();
  const Ray ray{{0, 0, 0}, {0, 0, -1}};
  EXPECT_EQ(query->firstHit(ray).triangle, 0u);
  EXPECT_EQ(query->batchCount(), 2u);
  const uint32_t first = 0;
  query->removeTriangles({&first, 1});
  query->commit();
  const Hit hit = query->firstHit(ray);
  EXPECT_EQ(hit.triangle, 1u);
  EXPECT_EQ(hit.t, 5.0f);
  EXPECT_EQ(query->batchCount(), 1u);
}

}  // namespace
}  // namespace vistream
