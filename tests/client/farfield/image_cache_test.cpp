#include "client/farfield/image_cache.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <set>
#include <string>

#include "client/render/camera.h"
#include "tests/common/support/camera_at.h"

// Oracles: exact direction geometry (azimuth and elevation of world
// directions, cameras aimed along a known direction) and hand-built histories
// of eyes and stored texels whose right plan follows from the header's rules.

namespace vistream {
namespace {

Camera makeCamera(glm::vec3 eye, float yaw, float pitch, int width = 160, int height = 120) {
  return testing::cameraAt(eye, yaw, pitch, width, height);
}

// World direction from azimuth (the camera's yaw convention: 0 looks along -Z,
// positive turns left) and elevation, radians.
glm::vec3 direction(double azimuth, double elevation) {
  return glm::vec3(glm::dvec3(-std::sin(azimuth) * std::cos(elevation), std::sin(elevation),
                              -std::cos(azimuth) * std::cos(elevation)));
}
double azimuthOf(glm::vec3 d) {
  return std::atan2(-double(d.x), -double(d.z));
}
double elevationOf(glm::vec3 d) {
  return std::atan2(double(d.y), std::hypot(double(d.x), double(d.z)));
}

// The texel is the same for every direction within 2e-4 rad of d in azimuth and
// elevation: d is not on a texel border, so float noise cannot move it.
bool awayFromTexelBorders(const PanoramicCache& cache, glm::vec3 d) {
  const double a = azimuthOf(d), e = elevationOf(d), eps = 2e-4;
  const int64_t t = cache.texelOf(d);
  for (double da : {-eps, 0.0, eps})
    for (double de : {-eps, 0.0, eps})
      if (cache.texelOf(direction(a + da, e + de)) != t) return false;
  return true;
}

std::vector<int64_t> texelsSeenBy(const PanoramicCache& cache, const Camera& cam, int x0 = 0,
                                  int x1 = -1) {
  if (x1 < 0) x1 = cam.width;
  std::vector<int64_t> texels;
  for (int y = 0; y < cam.height; ++y)
    for (int x = x0; x < x1; ++x)
      texels.push_back(cache.texelOf(cam.rayDirection(float(x) + 0.5f, float(y) + 0.5f)));
  return texels;
}

glm::u8vec3 colourOf(int64_t texel) {
  return {uint8_t(texel % 251), uint8_t(texel / 251 % 251), 7};
}

void storeTraced(PanoramicCache& cache, const std::vector<int64_t>& texels,
                 const std::vector<uint8_t>& trace) {
  for (size_t i = 0; i < texels.size(); ++i)
    if (trace[i] && texels[i] >= 0) cache.store(texels[i], colourOf(texels[i]));
}

TEST(PanoramicCache, MapsAWorldDirectionToTheSameTexelWhicheverCameraSawIt) {
  const Camera first = makeCamera({0, 0, 0}, 0, 0);
  const PanoramicCache cache(first.pixelAngle());
  std::mt19937 rng(1);
  auto U = [&](float a, float b) { return std::uniform_real_distribution<float>(a, b)(rng); };
  size_t checked = 0, samples = 0;
  for (int i = 0; i < 2000; ++i) {
    // A pixel of a camera with a random yaw sees direction d ...
    const Camera a = makeCamera({U(-5, 5), U(0, 5), U(-5, 5)}, U(-180, 180), U(-25, 25));
    const glm::vec3 d = a.rayDirection(U(0, 160), U(0, 120));
    ++samples;
    if (!awayFromTexelBorders(cache, d)) continue;
    ++checked;
    // ... which a camera aimed along d sees at its image centre ...
    const Camera b =
        makeCamera(a.eye, float(glm::degrees(azimuthOf(d))), float(glm::degrees(elevationOf(d))));
    EXPECT_EQ(cache.texelOf(b.rayDirection(80.0f, 60.0f)), cache.texelOf(d)) << "sample " << i;
    // ... and a camera turned 25 degrees to the left sees it right of its centre.
    const Camera c = makeCamera(a.eye, b.yawDeg + 25.0f, 0.0f);
    const glm::vec4 clip = c.viewProjection() * glm::vec4(c.eye + d, 1.0f);
    const float wx = (clip.x / clip.w * 0.5f + 0.5f) * 160.0f,
                wy = (0.5f - clip.y / clip.w * 0.5f) * 120.0f;
    ASSERT_GT(clip.w, 0.0f);
    EXPECT_EQ(cache.texelOf(c.rayDirection(wx, wy)), cache.texelOf(d)) << "sample " << i;
    // The length of a direction does not matter either.
    EXPECT_EQ(cache.texelOf(37.0f * d), cache.texelOf(d));
  }
  EXPECT_GT(checked, samples / 2);
}

TEST(PanoramicCache, GivesDirectionsMoreThanTwoTexelAnglesApartDifferentTexels) {
  const Camera cam = makeCamera({0, 0, 0}, 0, 0);
  for (float perPixel : {1.0f, 2.0f, 0.5f}) {
    PanoramicCacheOptions options;
    options.texelsPerPixel = perPixel;
    const PanoramicCache cache(cam.pixelAngle(), options);
    const double texelAngle = cam.pixelAngle() / perPixel;
    const double maxElevation = std::atan(options.maxSlope) - 1e-3;
    std::mt19937 rng(2);
    auto U = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
    size_t pairs = 0, same = 0;
    for (int i = 0; i < 20000; ++i) {
      const double a0 = U(-std::numbers::pi, std::numbers::pi), e0 = U(-maxElevation, maxElevation);
      // A neighbour 2-4 texel angles away in azimuth or in elevation, or a random direction.
      double a1 = a0, e1 = e0;
      const int kind = i % 3;
      if (kind == 0) a1 = a0 + (i % 2 ? 1 : -1) * U(2.05, 4.0) * texelAngle;
      if (kind == 1)
        e1 = std::clamp(e0 + (i % 2 ? 1 : -1) * U(2.05, 4.0) * texelAngle, -maxElevation,
                        maxElevation);
      if (kind == 2)
        a1 = U(-std::numbers::pi, std::numbers::pi), e1 = U(-maxElevation, maxElevation);
      const double da = std::abs(std::remainder(a1 - a0, 2.0 * std::numbers::pi)),
                   de = std::abs(e1 - e0);
      if (!(da > 2.0 * texelAngle || de > 2.0 * texelAngle)) continue;
      ++pairs;
      const int64_t t0 = cache.texelOf(direction(a0, e0)), t1 = cache.texelOf(direction(a1, e1));
      EXPECT_GE(t0, 0);
      EXPECT_GE(t1, 0);
      same += t0 == t1;
    }
    EXPECT_EQ(same, 0u) << "texels per pixel " << perPixel;
    EXPECT_GT(pairs, 10000u);
  }
}

TEST(PanoramicCache, LeavesDirectionsSteeperThanMaxSlopeOutsideTheBand) {
  const Camera cam = makeCamera({0, 0, 0}, 0, 0);
  const PanoramicCache cache(cam.pixelAngle());
  const float maxSlope = PanoramicCacheOptions{}.maxSlope;
  for (double az : {0.0, 1.0, -2.5, 3.1}) {
    const glm::vec3 h(-std::sin(az), 0.0, -std::cos(az));
    for (float s : {1.01f * maxSlope, 3.0f, 100.0f}) {
      EXPECT_EQ(cache.texelOf(h + glm::vec3(0, s, 0)), -1) << "slope " << s;
      EXPECT_EQ(cache.texelOf(h - glm::vec3(0, s, 0)), -1) << "slope " << -s;
    }
    for (float s : {0.0f, 0.5f, 0.99f * maxSlope}) {
      for (float sign : {1.0f, -1.0f}) {
        const int64_t t = cache.texelOf(h + glm::vec3(0, sign * s, 0));
        EXPECT_GE(t, 0) << "slope " << sign * s;
        EXPECT_LT(t, int64_t(cache.texelCount()));
      }
    }
  }
  EXPECT_EQ(cache.texelOf({0, 1, 0}), -1);
  EXPECT_EQ(cache.texelOf({0, -1, 0}), -1);
  EXPECT_EQ(cache.texelOf({0, 0, 0}), -1);
}

// The thesis's update strategy alone (every stored texel here has its own
// colour, so the edge rule would retrace all of them; it is tested below).
PanoramicCacheOptions thesisOnly() {
  PanoramicCacheOptions o;
  o.retraceEdges = false;
  return o;
}

class CachePlan : public ::testing::Test {
 protected:
  static constexpr float kMaxStale = 1.0f;
  Camera cam = makeCamera({10, 2, 10}, 25, 5);
  PanoramicCache cache{cam.pixelAngle(), thesisOnly()};
  std::vector<uint8_t> trace;

  // Plans the first frame of `cam` with no budget and stores every texel it
  // traces; returns the texels it sees.
  std::vector<int64_t> storeTheFirstView() {
    const std::vector<int64_t> texels = texelsSeenBy(cache, cam);
    cache.plan(cam.eye, texels, 0, kMaxStale, trace);
    storeTraced(cache, texels, trace);
    return texels;
  }

  // Expects a plan `s` over `n` texels that traces every one and reuses none.
  void expectTracesAll(const CachePlanStats& s, size_t n) const {
    EXPECT_EQ(s.mustTrace, n);
    EXPECT_EQ(s.reused, 0u);
    EXPECT_EQ(size_t(std::count(trace.begin(), trace.end(), uint8_t(1))), n);
  }
};

TEST_F(CachePlan, TracesEveryCandidateOnTheFirstFrame) {
  const std::vector<int64_t> texels = texelsSeenBy(cache, cam);
  const CachePlanStats s = cache.plan(cam.eye, texels, 100, kMaxStale, trace);
  EXPECT_EQ(s.candidates, texels.size());
  EXPECT_EQ(s.budgeted, 0u);
  expectTracesAll(s, texels.size());
}

TEST_F(CachePlan, ReusesEverythingFromTheSameEyeAndReturnsTheStoredColours) {
  const std::vector<int64_t> texels = storeTheFirstView();
  const CachePlanStats s = cache.plan(cam.eye, texels, 0, kMaxStale, trace);
  EXPECT_EQ(s.reused, texels.size());
  EXPECT_EQ(s.mustTrace + s.budgeted, 0u);
  EXPECT_EQ(std::count(trace.begin(), trace.end(), uint8_t(1)), 0);
  for (int64_t t : texels) ASSERT_EQ(cache.colour(t), colourOf(t));
  // Turning on the spot keeps what both views share.
  const Camera turned = makeCamera(cam.eye, cam.yawDeg + 20.0f, cam.pitchDeg);
  const std::vector<int64_t> after = texelsSeenBy(cache, turned);
  const std::set<int64_t> stored(texels.begin(), texels.end());
  const CachePlanStats t = cache.plan(cam.eye, after, 0, kMaxStale, trace);
  const size_t shared = size_t(
      std::count_if(after.begin(), after.end(), [&](int64_t x) { return stored.count(x) > 0; }));
  EXPECT_EQ(t.reused, shared);
  EXPECT_EQ(t.mustTrace, after.size() - shared);
  EXPECT_GT(shared, after.size() / 2);
}

TEST_F(CachePlan, RetracesEverythingAfterATeleportEvenWithoutBudget) {
  const std::vector<int64_t> texels = storeTheFirstView();
  const glm::vec3 away =
      cam.eye + glm::vec3(0.8f * kMaxStale, 0.0f, 0.8f * kMaxStale);  // 1.13 maxStale
  expectTracesAll(cache.plan(away, texels, 0, kMaxStale, trace), texels.size());
}

TEST_F(CachePlan, SpendsTheBudgetOnStaleButValidPixelsAfterASmallMove) {
  const std::vector<int64_t> texels = storeTheFirstView();
  const glm::vec3 moved = cam.eye + glm::vec3(0.3f, 0.0f, 0.0f);
  const size_t n = texels.size();
  for (size_t budget : {size_t(1), size_t(7), n / 3, n / 2 + 1, n - 1, n, 2 * n}) {
    SCOPED_TRACE("budget " + std::to_string(budget));
    const CachePlanStats s = cache.plan(moved, texels, budget, kMaxStale, trace);
    const size_t want = std::min(budget, n);
    EXPECT_EQ(s.mustTrace, 0u);
    EXPECT_LE(s.budgeted, want);
    EXPECT_GE(2 * s.budgeted, want);
    EXPECT_EQ(s.budgeted + s.reused, n);
    EXPECT_EQ(size_t(std::count(trace.begin(), trace.end(), uint8_t(1))), s.budgeted);
    EXPECT_EQ(s.degraded, budget < n);
  }
}

TEST_F(CachePlan, RetracesTheRecordsFarthestFromTheEyeFirst) {
  // The left columns are traced from A, the right ones from B; the viewer then
  // stands at C, 0.3 from A and 0.1 from B, with budget for A's pixels only.
  const std::vector<int64_t> left = texelsSeenBy(cache, cam, 0, 60);
  const std::set<int64_t> leftSet(left.begin(), left.end());
  std::vector<int64_t> right;
  for (int64_t t : texelsSeenBy(cache, cam, 100, 160))
    if (!leftSet.count(t)) right.push_back(t);
  const glm::vec3 a = cam.eye, b = a + glm::vec3(0.4f, 0.0f, 0.0f),
                  c = a + glm::vec3(0.3f, 0.0f, 0.0f);
  cache.plan(a, left, 0, kMaxStale, trace);
  storeTraced(cache, left, trace);
  cache.plan(b, right, 0, kMaxStale, trace);
  storeTraced(cache, right, trace);
  std::vector<int64_t> both = right;
  both.insert(both.end(), left.begin(), left.end());
  const CachePlanStats s = cache.plan(c, both, left.size(), kMaxStale, trace);
  EXPECT_EQ(s.mustTrace, 0u);
  EXPECT_EQ(s.budgeted, left.size());
  EXPECT_EQ(std::count(trace.begin(), trace.begin() + std::ptrdiff_t(right.size()), uint8_t(1)), 0);
  EXPECT_EQ(
      size_t(std::count(trace.begin() + std::ptrdiff_t(right.size()), trace.end(), uint8_t(1))),
      left.size());
}

TEST_F(CachePlan, RecyclesRecordsNoTexelPointsTo) {
  // A small view (few texels) and a viewer who moves every frame for longer than
  // there are texels: without recycling, every frame would leave a record behind.
  const Camera small = makeCamera({0, 2, 0}, 10, 0, 32, 24);
  PanoramicCache c(small.pixelAngle());
  std::set<int64_t> everStored;
  std::mt19937 rng(3);
  auto U = [&](float a, float b) { return std::uniform_real_distribution<float>(a, b)(rng); };
  Camera viewer = small;
  size_t worst = 0;
  for (int frame = 0; frame < 3000; ++frame) {
    viewer.eye += glm::vec3(0.05f, 0.0f, 0.0f);
    viewer.yawDeg = 10.0f + U(-3, 3);
    const std::vector<int64_t> texels = texelsSeenBy(c, viewer);
    c.plan(viewer.eye, texels, 60, kMaxStale, trace);
    storeTraced(c, texels, trace);
    for (size_t i = 0; i < texels.size(); ++i)
      if (trace[i] && texels[i] >= 0) everStored.insert(texels[i]);
    worst = std::max(worst, c.liveRecords());
    ASSERT_LE(c.liveRecords(), everStored.size() + 2) << "frame " << frame;
  }
  EXPECT_LT(worst, 3000u / 2);
}

// Beyond the thesis: a texel whose neighbours differ in colour is retraced
// once the view turned, since a pixel may then map to it from up to half a
// texel away; texels inside a uniform patch are reused.
TEST(CacheEdges, RetracesOnlyTexelsOnAColourEdgeAfterTheViewTurned) {
  const Camera cam = makeCamera({0, 2, 0}, 0, 0, 64, 48);
  PanoramicCache cache(cam.pixelAngle());
  std::vector<uint8_t> trace;
  const std::vector<int64_t> texels = texelsSeenBy(cache, cam);
  cache.plan(cam.eye, texels, 0, 1.0f, trace);
  // Two colours: the texels left of column u0 dark, the rest light.
  const int64_t columns = cache.dims().x;
  int64_t uMin = columns, uMax = 0;
  for (int64_t t : texels) {
    uMin = std::min(uMin, t % columns);
    uMax = std::max(uMax, t % columns);
  }
  const int64_t u0 = (uMin + uMax) / 2;
  auto colour = [&](int64_t t) { return t % columns < u0 ? glm::u8vec3(20) : glm::u8vec3(200); };
  for (size_t i = 0; i < texels.size(); ++i)
    if (trace[i] && texels[i] >= 0) cache.store(texels[i], colour(texels[i]));
  // Independent oracle: a stored texel is on the edge if its left or right
  // neighbour lies on the other side of u0 (rows share the colour).
  const std::set<int64_t> stored(texels.begin(), texels.end());
  auto onEdge = [&](int64_t t) {
    for (int64_t n : {t - 1, t + 1})
      if (stored.count(n) && colour(n) != colour(t)) return true;
    return false;
  };
  size_t expected = 0;
  for (int64_t t : texels) expected += onEdge(t);
  ASSERT_GT(expected, 0u);
  const CachePlanStats still = cache.plan(cam.eye, texels, 0, 1.0f, trace, /*viewTurned=*/false);
  EXPECT_EQ(still.edges, 0u) << "standing still, every pixel maps to its own texel";
  EXPECT_EQ(still.reused, texels.size());
  const CachePlanStats turned = cache.plan(cam.eye, texels, 0, 1.0f, trace, /*viewTurned=*/true);
  EXPECT_EQ(turned.edges, expected);
  for (size_t i = 0; i < texels.size(); ++i)
    EXPECT_EQ(trace[i] != 0, onEdge(texels[i])) << "texel " << texels[i];
}

}  // namespace
}  // namespace vistream
