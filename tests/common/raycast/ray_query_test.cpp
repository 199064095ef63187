// Ray queries: the brute-force oracle on cases with known answers, then every
// accelerated back end (Embree, kD-tree) against the oracle on random soups
// and on adversarial geometry: rays exactly through the shared edges and
// vertices of a grid mesh, hits exactly on tnear and tfar, degenerate
// triangles, ties, an empty scene, a scene far from the origin, batches and
// threads.
//
// Exactness: the grid meshes and the box have integer vertices and the rays
// through their edges have dyadic origins and directions (small multiples of
// 1/8, dominant component a power of two), so every back end's arithmetic on
// them, float or double, is exact and "on the edge" means exactly on it.
#include "common/raycast/ray_query.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "common/raycast/embree_ray_query.h"
#include "tests/common/support/triangle_soups.h"

namespace vistream {
namespace {

using testing::makeTriangles;
using testing::randomDirection;
using testing::Triangle;

// Triangles with random vertices around random centres in [lo, hi]^3.
FlatTriangles randomSoup(size_t count, uint32_t seed, glm::vec3 lo, glm::vec3 hi,
                         float size = 1.5f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::uniform_real_distribution<float> spread(-size, size);
  std::vector<Triangle> triangles(count);
  for (Triangle& t : triangles) {
    const glm::vec3 centre = lo + (hi - lo) * glm::vec3(unit(rng), unit(rng), unit(rng));
    for (glm::vec3& p : t) p = centre + glm::vec3(spread(rng), spread(rng), spread(rng));
  }
  return makeTriangles(triangles);
}

std::vector<Ray> randomRays(size_t count, uint32_t seed, glm::vec3 lo, glm::vec3 hi) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::vector<Ray> rays(count);
  for (Ray& r : rays) {
    r.org = lo + (hi - lo) * glm::vec3(unit(rng), unit(rng), unit(rng));
    r.dir = randomDirection(rng);
  }
  return rays;
}

// A regular grid of unit squares in the plane y = y0, x in [x0, x0+n],
// z in [z0, z0+n]. Square (i, j) is split along its diagonal from (i, j) to
// (i+1, j+1), so an interior vertex is shared by six triangles and an
// interior edge by two.
FlatTriangles gridMesh(int n, glm::vec3 corner) {
  std::vector<Triangle> triangles;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const glm::vec3 a = corner + glm::vec3(i, 0, j), b = corner + glm::vec3(i + 1, 0, j),
                      c = corner + glm::vec3(i + 1, 0, j + 1), d = corner + glm::vec3(i, 0, j + 1);
      triangles.push_back({a, b, c});
      triangles.push_back({a, c, d});
    }
  }
  return makeTriangles(triangles);
}

// Tolerance on t between a float back end and the double oracle, for unit
// directions in scenes of a few tens of metres (float ulps of the distances).
float tTolerance(float t) {
  return 2e-5f * std::max(1.0f, std::abs(t));
}

std::vector<uint32_t> trianglesOf(const std::vector<Hit>& hits) {
  std::vector<uint32_t> ids;
  for (const Hit& h : hits) ids.push_back(h.triangle);
  std::sort(ids.begin(), ids.end());
  return ids;
}

std::unique_ptr<RayQuery> makeBackEnd(const std::string& name, const FlatTriangles& triangles) {
  if (name == "embree") return makeEmbreeRayQuery(triangles);
  if (name == "kdtree") return makeKdTreeRayQuery(triangles);
  return makeBruteForceRayQuery(triangles);
}

// ---- the oracle on known answers ---------------------------------------------

TEST(BruteForceRayQuery, FindsTheKnownHitOfOneTriangle) {
  const FlatTriangles tris =
      makeTriangles({{glm::vec3(0, 0, 0), glm::vec3(2, 0, 0), glm::vec3(0, 2, 0)}});
  const auto query = makeBruteForceRayQuery(tris);
  EXPECT_STREQ(query->name(), "bruteforce");
  const Hit hit = query->firstHit(Ray{glm::vec3(0.5f, 0.5f, 4.0f), glm::vec3(0, 0, -2)});
  ASSERT_TRUE(hit.valid());
  EXPECT_EQ(hit.triangle, 0u);
  EXPECT_FLOAT_EQ(hit.t, 2.0f);  // in units of |dir| = 2
  EXPECT_FLOAT_EQ(hit.u, 0.25f);
  EXPECT_FLOAT_EQ(hit.v, 0.25f);
  EXPECT_EQ(hit.normal, glm::vec3(0, 0, 4));
  EXPECT_FALSE(query->firstHit(Ray{glm::vec3(1.5f, 1.5f, 4.0f), glm::vec3(0, 0, -1)}).valid());
}

TEST(BruteForceRayQuery, ReportsBothTrianglesOfAnEdgeAndResolvesTheTieToTheSmallerIndex) {
  // Two triangles sharing the edge x = y, listed so the second one is found first.
  const FlatTriangles tris =
      makeTriangles({{glm::vec3(0, 0, 0), glm::vec3(1, 1, 0), glm::vec3(0, 1, 0)},
                     {glm::vec3(0, 0, 0), glm::vec3(1, 0, 0), glm::vec3(1, 1, 0)}});
  const auto query = makeBruteForceRayQuery(tris);
  const Ray ray{glm::vec3(0.5f, 0.5f, 1.0f), glm::vec3(0, 0, -1)};
  EXPECT_EQ(query->firstHit(ray).triangle, 0u);
  std::vector<Hit> hits;
  query->allHits(ray, hits);
  EXPECT_EQ(trianglesOf(hits), (std::vector<uint32_t>{0, 1}));
}

TEST(BruteForceRayQuery, SortsAllHitsByDistance) {
  std::vector<Triangle> planes;
  for (float z : {3.0f, -1.0f, 1.0f})
    planes.push_back({glm::vec3(-1, -1, z), glm::vec3(1, -1, z), glm::vec3(0, 1, z)});
  const FlatTriangles tris = makeTriangles(planes);
  std::vector<Hit> hits;
  makeBruteForceRayQuery(tris)->allHits(Ray{glm::vec3(0, 0, 5), glm::vec3(0, 0, -1)}, hits);
  ASSERT_EQ(hits.size(), 3u);
  EXPECT_EQ(hits[0].triangle, 0u);
  EXPECT_EQ(hits[1].triangle, 2u);
  EXPECT_EQ(hits[2].triangle, 1u);
  EXPECT_FLOAT_EQ(hits[2].t, 6.0f);
}

TEST(RayQuery, DefaultBatchesAnswerLikeSingleRays) {
  const FlatTriangles tris = randomSoup(200, 7, glm::vec3(0), glm::vec3(10));
  const auto query = makeBruteForceRayQuery(tris);  // uses the default batches
  const std::vector<Ray> rays = randomRays(100, 8, glm::vec3(-2), glm::vec3(12));
  std::vector<Hit> hits(rays.size());
  std::vector<uint8_t> occluded(rays.size());
  query->firstHits(rays, hits);
  query->occludedMany(rays, occluded);
  for (size_t i = 0; i < rays.size(); ++i) {
    EXPECT_EQ(hits[i].triangle, query->firstHit(rays[i]).triangle);
    EXPECT_EQ(occluded[i] != 0, query->occluded(rays[i]));
  }
}

// ---- accelerated back ends against the oracle -----------------------------------

class AcceleratedRayQuery : public ::testing::TestWithParam<std::string> {
 protected:
  std::unique_ptr<RayQuery> make(const FlatTriangles& triangles) const {
    return makeBackEnd(GetParam(), triangles);
  }
};

// Compares first hits and occlusion of `rays` with the oracle. Where the two
// nearest triangles differ, they must tie within float tolerance.
void expectSameFirstHits(const RayQuery& query, const RayQuery& oracle,
                         const std::vector<Ray>& rays, float tolerance = 0.0f) {
  size_t hitCount = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Hit got = query.firstHit(rays[i]), want = oracle.firstHit(rays[i]);
    ASSERT_EQ(got.valid(), want.valid()) << "ray " << i << ": " << query.name() << " hits "
                                         << got.triangle << ", the oracle " << want.triangle;
    EXPECT_EQ(query.occluded(rays[i]), want.valid()) << "ray " << i;
    if (!want.valid()) continue;
    ++hitCount;
    const float tol = tolerance > 0.0f ? tolerance : tTolerance(want.t);
    EXPECT_NEAR(got.t, want.t, tol) << "ray " << i << ", triangle " << got.triangle;
    if (got.triangle != want.triangle) {
      // Only a near tie may pick another triangle: it must be hit there too.
      std::vector<Hit> all;
      oracle.allHits(rays[i], all);
      const auto other = std::find_if(all.begin(), all.end(),
                                      [&](const Hit& h) { return h.triangle == got.triangle; });
      EXPECT_TRUE(other != all.end() && std::abs(other->t - want.t) <= tol)
          << "ray " << i << ": " << query.name() << " hits " << got.triangle << " at " << got.t
          << ", the oracle " << want.triangle << " at " << want.t;
    }
  }
  EXPECT_GT(hitCount, rays.size() / 10) << "the test rays should mostly hit something";
}

void expectSameHitSets(const RayQuery& query, const RayQuery& oracle, const std::vector<Ray>& rays,
                       float tolerance = 0.0f) {
  std::vector<Hit> got, want;
  for (size_t i = 0; i < rays.size(); ++i) {
    query.allHits(rays[i], got);
    oracle.allHits(rays[i], want);
    ASSERT_EQ(trianglesOf(got), trianglesOf(want)) << "ray " << i;
    for (size_t k = 0; k < got.size(); ++k) {
      const float tol = tolerance > 0.0f ? tolerance : tTolerance(want[k].t);
      EXPECT_NEAR(got[k].t, want[k].t, tol) << "ray " << i << ", hit " << k;
      if (k > 0) {
        EXPECT_TRUE(got[k - 1].t < got[k].t ||
                    (got[k - 1].t == got[k].t && got[k - 1].triangle < got[k].triangle))
            << "ray " << i << ": hits not sorted by t then triangle";
      }
    }
  }
}

TEST_P(AcceleratedRayQuery, AgreesWithBruteForceOnFirstHitsAndOcclusionInARandomSoup) {
  const FlatTriangles tris = randomSoup(3000, 1, glm::vec3(0), glm::vec3(20));
  const auto query = make(tris);
  EXPECT_EQ(std::string(query->name()), GetParam());
  expectSameFirstHits(*query, *makeBruteForceRayQuery(tris),
                      randomRays(1500, 2, glm::vec3(-5), glm::vec3(25)));
}

TEST_P(AcceleratedRayQuery, ReportsTheSameHitSetsAsBruteForceInARandomSoup) {
  const FlatTriangles tris = randomSoup(3000, 3, glm::vec3(0), glm::vec3(20));
  expectSameHitSets(*make(tris), *makeBruteForceRayQuery(tris),
                    randomRays(800, 4, glm::vec3(-5), glm::vec3(25)));
}

TEST_P(AcceleratedRayQuery, AgreesWithBruteForceFarFromTheOrigin) {
  // Local coordinates of a few thousand metres: float spacing there is
  // 1.2e-4 to 4.9e-4 m, hence the absolute tolerance.
  const glm::vec3 lo(2000, 1000, 6000), hi(2030, 1030, 6030);
  const FlatTriangles tris = randomSoup(2000, 5, lo, hi);
  const auto query = make(tris);
  const auto oracle = makeBruteForceRayQuery(tris);
  const std::vector<Ray> rays = randomRays(1000, 6, lo - 5.0f, hi + 5.0f);
  expectSameFirstHits(*query, *oracle, rays, 4e-3f);
  expectSameHitSets(*query, *oracle, std::vector<Ray>(rays.begin(), rays.begin() + 300), 4e-3f);
}

// Rays exactly through the interior edges and vertices of a grid mesh, from
// above and below at dyadic slopes, with the number of triangles sharing each.
struct SeamRay {
  Ray ray;
  size_t sharing;  // triangles that contain the point the ray passes through
};

std::vector<SeamRay> seamRays(int n, glm::vec3 corner) {
  const std::array<glm::vec3, 6> directions = {
      glm::vec3(0, -1, 0),      glm::vec3(0.25f, -1, -0.5f), glm::vec3(-0.75f, -1, 0.25f),
      glm::vec3(0.5f, 1, 0.5f), glm::vec3(-2, -4, 1),        glm::vec3(1, 0.5f, -0.25f)};
  std::vector<SeamRay> rays;
  for (int i = 1; i < n; ++i) {
    for (int j = 1; j < n; ++j) {
      const glm::vec3 v = corner + glm::vec3(i, 0, j);
      const std::array<SeamRay, 4> targets = {
          SeamRay{Ray{v}, 6},                                // vertex
          SeamRay{Ray{v + glm::vec3(0.25f, 0, 0)}, 2},       // edge along x
          SeamRay{Ray{v + glm::vec3(0, 0, 0.5f)}, 2},        // edge along z
          SeamRay{Ray{v + glm::vec3(0.75f, 0, 0.75f)}, 2}};  // diagonal
      for (const SeamRay& target : targets) {
        for (const glm::vec3& d : directions) {
          SeamRay s = target;
          s.ray.dir = d;
          s.ray.org = target.ray.org - 4.0f * d;  // the seam at t = 4
          rays.push_back(s);
        }
      }
    }
  }
  return rays;
}

void expectSeamsClosed(const RayQuery& query, const RayQuery& oracle, const FlatTriangles& tris,
                       const std::vector<SeamRay>& rays) {
  std::vector<Ray> batch;
  for (const SeamRay& s : rays) batch.push_back(s.ray);
  std::vector<Hit> batchHits(batch.size());
  query.firstHits(batch, batchHits);
  std::vector<Hit> got, want;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Ray& ray = rays[i].ray;
    oracle.allHits(ray, want);
    ASSERT_EQ(want.size(), rays[i].sharing) << "the oracle is exact on seam ray " << i;
    const Hit first = query.firstHit(ray);
    ASSERT_TRUE(first.valid()) << query.name() << " lets seam ray " << i << " through";
    EXPECT_EQ(first.triangle, oracle.firstHit(ray).triangle)
        << "seam ray " << i << ": ties resolve to the smaller index";
    EXPECT_FLOAT_EQ(first.t, 4.0f) << "seam ray " << i;
    EXPECT_EQ(batchHits[i].triangle, first.triangle) << "seam ray " << i << " in a batch";
    EXPECT_TRUE(query.occluded(ray)) << "seam ray " << i;
    query.allHits(ray, got);
    EXPECT_EQ(trianglesOf(got), trianglesOf(want))
        << "seam ray " << i << " must report every triangle sharing the seam";
  }
  EXPECT_GT(tris.size(), 0u);
}

TEST_P(AcceleratedRayQuery, ReportsEveryTriangleAroundSharedEdgesAndVerticesOfAGridMesh) {
  const glm::vec3 corner(-3, 2, -4);
  const FlatTriangles tris = gridMesh(6, corner);
  expectSeamsClosed(*make(tris), *makeBruteForceRayQuery(tris), tris, seamRays(6, corner));
}

TEST_P(AcceleratedRayQuery, ReportsEveryTriangleAroundSeamsOfAGridMeshFarFromTheOrigin) {
  const glm::vec3 corner(3000, 10, 7000);
  const FlatTriangles tris = gridMesh(4, corner);
  expectSeamsClosed(*make(tris), *makeBruteForceRayQuery(tris), tris, seamRays(4, corner));
}

TEST_P(AcceleratedRayQuery, AgreesWithBruteForceAtTheEdgesAndCornersOfABox) {
  // The closed box [0, 2]^3, each face two triangles; rays aimed at surface
  // points on a half-metre lattice: corners, edges (folded seams), face
  // diagonals (flat seams) and face interiors, from dyadic directions.
  std::vector<Triangle> faces;
  for (int axis = 0; axis < 3; ++axis) {
    for (float side : {0.0f, 2.0f}) {
      std::array<glm::vec3, 4> q;
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (int k = 0; k < 4; ++k) {
        q[size_t(k)][axis] = side;
        q[size_t(k)][u] = (k == 1 || k == 2) ? 2.0f : 0.0f;
        q[size_t(k)][v] = (k >= 2) ? 2.0f : 0.0f;
      }
      faces.push_back({q[0], q[1], q[2]});
      faces.push_back({q[0], q[2], q[3]});
    }
  }
  const FlatTriangles tris = makeTriangles(faces);
  const auto query = make(tris);
  const auto oracle = makeBruteForceRayQuery(tris);
  const std::array<glm::vec3, 4> directions = {glm::vec3(-1, -0.5f, 0.25f),
                                               glm::vec3(0.5f, 1, -0.75f),
                                               glm::vec3(0.125f, -0.25f, 1), glm::vec3(-1, 0, 0)};
  std::vector<Hit> got, want;
  size_t rays = 0;
  for (int i = 0; i <= 4; ++i) {
    for (int j = 0; j <= 4; ++j) {
      for (int k = 0; k <= 4; ++k) {
        if (i % 4 != 0 && j % 4 != 0 && k % 4 != 0) continue;  // inside, not on the surface
        const glm::vec3 target = 0.5f * glm::vec3(i, j, k);
        for (const glm::vec3& dir : directions) {
          const Ray ray{target - 4.0f * dir, dir};
          ++rays;
          const Hit first = query->firstHit(ray), expected = oracle->firstHit(ray);
          ASSERT_TRUE(expected.valid());
          EXPECT_EQ(first.triangle, expected.triangle) << "towards " << i << j << k;
          EXPECT_FLOAT_EQ(first.t, expected.t) << "towards " << i << j << k;
          query->allHits(ray, got);
          oracle->allHits(ray, want);
          EXPECT_EQ(trianglesOf(got), trianglesOf(want)) << "towards " << i << j << k;
        }
      }
    }
  }
  EXPECT_EQ(rays, 98u * directions.size());
}

TEST_P(AcceleratedRayQuery, NeverLetsARayThroughTheSeamsOfATiltedMesh) {
  // A grid tilted out of every axis plane, so the vertices are not exact and
  // the rays only nearly pass through the seams: nothing may slip through.
  const FlatTriangles grid = gridMesh(8, glm::vec3(0));
  const glm::mat3 tilt = glm::mat3(glm::vec3(0.8f, 0.36f, -0.48f), glm::vec3(-0.6f, 0.48f, -0.64f),
                                   glm::vec3(0.0f, 0.8f, 0.6f));
  FlatTriangles tris = grid;
  for (glm::vec3& p : tris.positions) p = tilt * (p * 1.37f) + glm::vec3(0.1f, 0.2f, 0.3f);
  const auto query = make(tris);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  int misses = 0;
  for (int k = 0; k < 4000; ++k) {
    // A random point on a random interior edge, approached from a random side.
    const uint32_t t = uint32_t(unit(rng) * float(tris.size() - 1));
    const int e = int(unit(rng) * 2.999f);
    const glm::vec3 a = tris.vertex(t, e), b = tris.vertex(t, (e + 1) % 3);
    const glm::vec3 onEdge = glm::mix(a, b, unit(rng));
    const glm::vec3 gridPoint =
        (glm::transpose(tilt) * (onEdge - glm::vec3(0.1f, 0.2f, 0.3f))) / 1.37f;
    if (gridPoint.x < 0.01f || gridPoint.x > 7.99f || gridPoint.z < 0.01f || gridPoint.z > 7.99f)
      continue;  // the outer boundary is not a seam
    Ray ray;
    ray.dir = randomDirection(rng);
    if (std::abs(glm::dot(ray.dir, tilt[1])) < 0.05f) continue;  // grazing
    ray.org = onEdge - 10.0f * ray.dir;
    if (!query->firstHit(ray).valid()) ++misses;
  }
  EXPECT_EQ(misses, 0);
}

TEST_P(AcceleratedRayQuery, HonoursTnearAndTfarAsAClosedInterval) {
  const FlatTriangles tris = gridMesh(4, glm::vec3(0));
  const auto query = make(tris);
  for (const glm::vec3& dir : {glm::vec3(0, -1, 0), glm::vec3(0.25f, -0.5f, 0.125f)}) {
    Ray ray;
    ray.dir = dir;
    ray.org = glm::vec3(1.375f, 0, 2.625f) - 5.0f * dir;  // the grid at t = 5 exactly
    std::vector<Hit> hits;
    for (auto [tnear, tfar, hit] :
         {std::tuple{0.0f, 5.0f, true}, std::tuple{5.0f, 5.0f, true}, std::tuple{5.0f, 9.0f, true},
          std::tuple{0.0f, 4.999f, false}, std::tuple{5.001f, 9.0f, false}}) {
      ray.tnear = tnear;
      ray.tfar = tfar;
      const Hit first = query->firstHit(ray);
      EXPECT_EQ(first.valid(), hit) << "[" << tnear << ", " << tfar << "]";
      EXPECT_EQ(query->occluded(ray), hit) << "[" << tnear << ", " << tfar << "]";
      query->allHits(ray, hits);
      EXPECT_EQ(hits.size(), hit ? 1u : 0u) << "[" << tnear << ", " << tfar << "]";
      if (hit) {
        EXPECT_FLOAT_EQ(first.t, 5.0f);
      }
    }
  }
}

TEST_P(AcceleratedRayQuery, NeverHitsDegenerateTriangles) {
  // Degenerate triangles in front of a wall at z = 0, each exactly in the path
  // of one ray: a repeated vertex, three collinear vertices, and a needle too
  // thin to count (area 1e-13 of its squared length) that float arithmetic
  // would still hit.
  const std::vector<Triangle> triangles = {
      {glm::vec3(0, 0, 1), glm::vec3(0, 0, 1), glm::vec3(1, 1, 1)},
      {glm::vec3(-1, -1, 2), glm::vec3(1, 1, 2), glm::vec3(3, 3, 2)},
      {glm::vec3(0, 0, 3), glm::vec3(1, 0, 3), glm::vec3(0.5f, 1e-13f, 3)},
      {glm::vec3(-4, -4, 0), glm::vec3(4, -4, 0), glm::vec3(0, 4, 0)}};
  const FlatTriangles tris = makeTriangles(triangles);
  ASSERT_EQ(tris.degenerate, (std::vector<uint8_t>{1, 1, 1, 0}));
  const auto query = make(tris);
  const std::vector<glm::vec3> throughDegenerate = {glm::vec3(0, 0, 1), glm::vec3(0.5f, 0.5f, 2),
                                                    glm::vec3(0.5f, 0.5e-13f, 3)};
  std::vector<Hit> hits;
  for (const glm::vec3& p : throughDegenerate) {
    const Ray ray{p + glm::vec3(0, 0, 2), glm::vec3(0, 0, -1)};
    const Hit first = query->firstHit(ray);
    EXPECT_EQ(first.triangle, 3u) << "through " << p.x << " " << p.y << " " << p.z;
    query->allHits(ray, hits);
    EXPECT_EQ(trianglesOf(hits), std::vector<uint32_t>{3u});
    Ray shortRay = ray;
    shortRay.tfar = 2.5f;  // reaches the degenerate triangle (t = 2), not the wall (t >= 3)
    EXPECT_FALSE(query->occluded(shortRay));
    EXPECT_FALSE(query->firstHit(shortRay).valid());
  }
}

TEST_P(AcceleratedRayQuery, ResolvesTiesToTheSmallerTriangleIndex) {
  // The same square twice, as triangles 0-1 and 2-3 in another vertex order,
  // then another copy of triangle 0 at the end: every ray meets two, three or
  // (on the diagonal) five triangles at the same t, exactly, since origins
  // and directions are dyadic.
  const glm::vec3 a(0, 0, 0), b(2, 0, 0), c(2, 2, 0), d(0, 2, 0);
  const FlatTriangles tris = makeTriangles({{a, b, c}, {a, c, d}, {c, a, b}, {d, a, c}, {b, c, a}});
  const auto query = make(tris);
  const auto oracle = makeBruteForceRayQuery(tris);
  for (const glm::vec3& p :
       {glm::vec3(1.5f, 0.5f, 0), glm::vec3(0.5f, 1.5f, 0), glm::vec3(1, 1, 0)}) {
    for (float dz : {-1.0f, 1.0f}) {
      const glm::vec3 dir(0.25f, 0.5f, dz);
      const Ray ray{p - 3.0f * dir, dir};
      const Hit first = query->firstHit(ray);
      const Hit want = oracle->firstHit(ray);
      EXPECT_TRUE(want.triangle == 0u || want.triangle == 1u);
      EXPECT_EQ(first.triangle, want.triangle);
      EXPECT_FLOAT_EQ(first.t, 3.0f);
    }
  }
}

TEST_P(AcceleratedRayQuery, ReportsTheGeometricNormalOfTheContract) {
  const FlatTriangles tris = randomSoup(500, 9, glm::vec3(0), glm::vec3(10));
  const auto query = make(tris);
  for (const Ray& ray : randomRays(300, 10, glm::vec3(-2), glm::vec3(12))) {
    const Hit hit = query->firstHit(ray);
    if (!hit.valid()) continue;
    const glm::vec3 a = tris.vertex(hit.triangle, 0), b = tris.vertex(hit.triangle, 1),
                    c = tris.vertex(hit.triangle, 2);
    const glm::vec3 n = glm::cross(b - a, c - a);
    EXPECT_LE(glm::length(hit.normal - n), 1e-5f * glm::length(n)) << "triangle " << hit.triangle;
    // u, v locate the hit point.
    const glm::vec3 p = ray.org + hit.t * ray.dir;
    const glm::vec3 q = (1.0f - hit.u - hit.v) * a + hit.u * b + hit.v * c;
    EXPECT_LE(glm::length(p - q), 1e-4f) << "triangle " << hit.triangle;
  }
}

TEST_P(AcceleratedRayQuery, MissesEverythingInAnEmptyScene) {
  const uint64_t embreeErrors = embreeErrorCount();
  const FlatTriangles empty;
  const auto query = make(empty);
  const std::vector<Ray> rays = randomRays(50, 12, glm::vec3(-1), glm::vec3(1));
  std::vector<Hit> hits(rays.size());
  std::vector<uint8_t> occluded(rays.size(), 1);
  query->firstHits(rays, hits);
  query->occludedMany(rays, occluded);
  std::vector<Hit> all;
  for (size_t i = 0; i < rays.size(); ++i) {
    EXPECT_FALSE(query->firstHit(rays[i]).valid());
    EXPECT_FALSE(query->occluded(rays[i]));
    query->allHits(rays[i], all);
    EXPECT_TRUE(all.empty());
    EXPECT_FALSE(hits[i].valid());
    EXPECT_EQ(occluded[i], 0);
  }
  EXPECT_EQ(embreeErrorCount(), embreeErrors);
}

TEST_P(AcceleratedRayQuery, AnswersBatchesLikeSingleRays) {
  const FlatTriangles tris = randomSoup(1000, 13, glm::vec3(0), glm::vec3(15));
  const auto query = make(tris);
  // Not a multiple of any chunk size, with rays the query cannot trace mixed in.
  std::vector<Ray> rays = randomRays(1001, 14, glm::vec3(-3), glm::vec3(18));
  rays[17].dir = glm::vec3(0);
  rays[500].tnear = 2.0f;
  rays[500].tfar = 1.0f;
  rays[501].tfar = 3.0f;
  std::vector<Hit> hits(rays.size());
  std::vector<uint8_t> occluded(rays.size());
  query->firstHits(rays, hits);
  query->occludedMany(rays, occluded);
  for (size_t i = 0; i < rays.size(); ++i) {
    const Hit single = query->firstHit(rays[i]);
    EXPECT_EQ(hits[i].triangle, single.triangle) << "ray " << i;
    EXPECT_EQ(hits[i].t, single.t) << "ray " << i;
    EXPECT_EQ(occluded[i] != 0, query->occluded(rays[i])) << "ray " << i;
  }
  EXPECT_FALSE(hits[17].valid());
  EXPECT_FALSE(hits[500].valid());
  query->firstHits({}, {});
  query->occludedMany({}, {});
}

TEST_P(AcceleratedRayQuery, GivesTheSameAnswersFromSeveralThreads) {
  const FlatTriangles tris = randomSoup(2000, 15, glm::vec3(0), glm::vec3(20));
  const auto query = make(tris);
  const std::vector<Ray> rays = randomRays(2000, 16, glm::vec3(-5), glm::vec3(25));
  std::vector<Hit> reference(rays.size());
  std::vector<size_t> referenceHitCount(rays.size());
  std::vector<Hit> all;
  for (size_t i = 0; i < rays.size(); ++i) {
    reference[i] = query->firstHit(rays[i]);
    query->allHits(rays[i], all);
    referenceHitCount[i] = all.size();
  }

  constexpr int kThreads = 4;
  std::vector<int> mismatches(kThreads, 0);
  std::vector<std::thread> threads;
  for (int k = 0; k < kThreads; ++k) {
    threads.emplace_back([&, k] {
      std::vector<Hit> threadAll;
      std::vector<Hit> batch(rays.size());
      query->firstHits(rays, batch);
      // Each thread walks the rays from a different start, mixing query types.
      for (size_t n = 0; n < rays.size(); ++n) {
        const size_t i = (n + size_t(k) * 499) % rays.size();
        const Hit hit = query->firstHit(rays[i]);
        query->allHits(rays[i], threadAll);
        const bool same = hit.triangle == reference[i].triangle && hit.t == reference[i].t &&
                          batch[i].triangle == reference[i].triangle &&
                          query->occluded(rays[i]) == reference[i].valid() &&
                          threadAll.size() == referenceHitCount[i];
        if (!same) ++mismatches[size_t(k)];
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(mismatches, std::vector<int>(kThreads, 0));
}

INSTANTIATE_TEST_SUITE_P(BackEnds, AcceleratedRayQuery, ::testing::Values("embree", "kdtree"),
                         [](const ::testing::TestParamInfo<std::string>& backEnd) {
                           return backEnd.param;
                         });

}  // namespace
}  // namespace vistream
