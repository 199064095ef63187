#include "client/render/soft_raster.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <numeric>
#include <random>
#include <sstream>
#include <string>

#include "common/raycast/ray_query.h"
#include "tests/common/support/camera_at.h"
#include "tests/common/support/triangle_soups.h"

// Oracles: a brute-force ray cast through each pixel centre (Camera::rayDirection
// has a forward component of exactly 1, so the ray parameter t is view depth and
// tnear = zNear is the near plane); exact window-space geometry in double (a
// triangle clipped at the near plane and projected through the camera basis)
// to tell which pixel centres lie within 0.5 px of an edge; and triangles whose
// corners sit on the rays through chosen window points, whose projection is
// therefore known exactly.

namespace vistream {
namespace {

using testing::addTriangle;

std::vector<uint32_t> allOf(const FlatTriangles& f) {
  std::vector<uint32_t> v(f.size());
  std::iota(v.begin(), v.end(), 0u);
  return v;
}

// The point at view depth `depth` on the ray through window point w (negative: behind the eye).
glm::vec3 onPixelRay(const Camera& c, glm::dvec2 w, float depth) {
  return c.eye + depth * c.rayDirection(float(w.x), float(w.y));
}

Camera rasterCamera(glm::vec3 eye, float yaw, float pitch) {
  return testing::cameraAt(eye, yaw, pitch, 160, 120);
}

// Ray-cast questions about one pixel of one camera.
struct RayOracle {
  const Camera& camera;
  const RayQuery& rays;

  Ray through(double px, double py) const {
    return Ray{camera.eye, camera.rayDirection(float(px), float(py)), camera.zNear, camera.zFar};
  }
  Hit first(double px, double py) const { return rays.firstHit(through(px, py)); }
  // Both triangles are hit through the centre at depths within a relative 1e-3.
  bool depthTie(uint32_t a, uint32_t b, int x, int y) const {
    std::vector<Hit> all;
    rays.allHits(through(x + 0.5, y + 0.5), all);
    float ta = -1.0f, tb = -1.0f;
    for (const Hit& h : all) {
      if (h.triangle == a) ta = h.t;
      if (h.triangle == b) tb = h.t;
    }
    return ta >= 0.0f && tb >= 0.0f && std::abs(ta - tb) <= 1e-3f * std::max(ta, tb);
  }
};

// Exact window-space geometry (double): the outline of the part of triangle t in
// front of the near plane, projected through the camera's basis.
std::vector<glm::dvec2> windowOutline(const Camera& c, const FlatTriangles& f, uint32_t t) {
  const glm::dvec3 right(c.right()), up(c.up()), forward(c.forward()), eye(c.eye);
  std::vector<glm::dvec3> in, out;  // view space: (right, up, depth)
  for (int k = 0; k < 3; ++k) {
    const glm::dvec3 v = glm::dvec3(f.vertex(t, k)) - eye;
    in.emplace_back(glm::dot(v, right), glm::dot(v, up), glm::dot(v, forward));
  }
  const double zNear = c.zNear;
  for (size_t i = 0; i < in.size(); ++i) {
    const glm::dvec3 a = in[i], b = in[(i + 1) % in.size()];
    if (a.z >= zNear) out.push_back(a);
    if ((a.z >= zNear) != (b.z >= zNear)) out.push_back(a + (zNear - a.z) / (b.z - a.z) * (b - a));
  }
  const double t2 = std::tan(0.5 * glm::radians(double(c.vfovDeg)));
  const double aspect = double(c.width) / double(c.height);
  std::vector<glm::dvec2> w;
  for (const glm::dvec3& v : out)
    w.emplace_back((v.x / v.z / (t2 * aspect) + 1.0) * 0.5 * c.width,
                   (1.0 - v.y / v.z / t2) * 0.5 * c.height);
  return w;
}

// Distance (px) from p to the nearest edge of an outline; infinity if it is empty.
double outlineDistance(const std::vector<glm::dvec2>& poly, glm::dvec2 p) {
  double best = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < poly.size(); ++i) {
    const glm::dvec2 a = poly[i], e = poly[(i + 1) % poly.size()] - a;
    const double len2 = glm::dot(e, e);
    const double s = len2 > 0 ? std::clamp(glm::dot(p - a, e) / len2, 0.0, 1.0) : 0.0;
    best = std::min(best, glm::length(a + s * e - p));
  }
  return best;
}

// True if an edge of triangle t passes within `px` of the centre of pixel (x, y).
bool edgeNear(const Camera& c, const FlatTriangles& f, uint32_t t, int x, int y, double px) {
  return t != kNoTriangle && outlineDistance(windowOutline(c, f, t), {x + 0.5, y + 0.5}) < px;
}

// A seeded soup in front of (and partly behind) the camera: ordinary triangles,
// slivers under a pixel wide, triangles crossing the near plane and large ones
// crossing the image border.
FlatTriangles randomSoup(const Camera& cam, uint32_t seed, int n) {
  std::mt19937 rng(seed);
  auto U = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  const double W = cam.width, H = cam.height;
  FlatTriangles f;
  for (int i = 0; i < n; ++i) {
    // Mostly ordinary triangles and slivers; a few large ones and a few crossing
    // the near plane (which cover much of the image), so some pixels stay empty.
    const int kind = i % 50 == 8 ? 8 : i % 25 == 9 ? 9 : i % 10 >= 8 ? i % 10 - 8 : i % 10;
    const glm::dvec2 c{U(-0.2 * W, 1.2 * W), U(-0.2 * H, 1.2 * H)};
    const double depth = std::exp(U(std::log(1.0), std::log(60.0)));
    std::array<glm::dvec2, 3> p;
    std::array<double, 3> z;
    if (kind < 6) {  // ordinary
      for (int k = 0; k < 3; ++k) {
        p[size_t(k)] = c + glm::dvec2(U(-25, 25), U(-25, 25));
        z[size_t(k)] = depth * U(0.7, 1.3);
      }
    } else if (kind < 8) {  // sliver: long and less than a pixel wide
      const double a = U(0, 6.283185307), len = U(20, 150), w = U(0.01, 0.8);
      const glm::dvec2 along(std::cos(a), std::sin(a)), across(-along.y, along.x);
      p = {c, c + len * along, c + 0.5 * len * along + w * across};
      z = {depth, depth * U(0.8, 1.2), depth * U(0.8, 1.2)};
    } else if (kind == 8) {  // crossing the near plane: one or two corners behind the eye
      for (int k = 0; k < 3; ++k) p[size_t(k)] = c + glm::dvec2(U(-60, 60), U(-60, 60));
      z = {depth, U(-5.0, 0.05), U(0.0, 1.0) < 0.5 ? depth * U(0.5, 1.5) : U(-5.0, 0.05)};
    } else {  // large, over the image border
      for (int k = 0; k < 3; ++k) {
        p[size_t(k)] = c + glm::dvec2(U(-150, 150), U(-150, 150));
        z[size_t(k)] = depth * U(0.7, 1.3);
      }
    }
    addTriangle(f, onPixelRay(cam, p[0], float(z[0])), onPixelRay(cam, p[1], float(z[1])),
                onPixelRay(cam, p[2], float(z[2])));
  }
  return f;
}

Camera randomCamera(uint32_t seed) {
  std::mt19937 rng(seed * 7919u + 1u);
  auto U = [&](float a, float b) { return std::uniform_real_distribution<float>(a, b)(rng); };
  return rasterCamera({U(-20, 20), U(0, 10), U(-20, 20)}, U(-180, 180), U(-30, 30));
}

// Triangles the rasterizer has drawn from one camera, with the brute-force
// ray oracle over the same triangles. The oracle points into the object, so
// it stays where it is built.
struct DrawnTriangles {
  const Camera cam;
  const FlatTriangles soup;
  const std::unique_ptr<RayQuery> rays;
  const RayOracle oracle;
  IdBuffer ids;

  DrawnTriangles(SoftwareRasterizer& raster, const Camera& camera, FlatTriangles triangles)
      : cam(camera),
        soup(std::move(triangles)),
        rays(makeBruteForceRayQuery(soup)),
        oracle{cam, *rays} {
    raster.draw(cam, soup, allOf(soup), ids);
  }
  // The random soup of `seed` (300 triangles) seen from the random camera of `seed`.
  DrawnTriangles(SoftwareRasterizer& raster, uint32_t seed)
      : DrawnTriangles(raster, randomCamera(seed), seed) {}
  DrawnTriangles(SoftwareRasterizer& raster, const Camera& camera, uint32_t seed)
      : DrawnTriangles(raster, camera, randomSoup(camera, seed, 300)) {}
  DrawnTriangles(const DrawnTriangles&) = delete;
  DrawnTriangles& operator=(const DrawnTriangles&) = delete;
};

// Exact window-space geometry: the signed distance (px) from p to the nearest
// edge line of a convex polygon, positive inside.
// True if p lies within `margin` of the polygon's bounding box.
template <size_t N>
bool withinBounds(const std::array<glm::dvec2, N>& poly, glm::dvec2 p, double margin) {
  glm::dvec2 lo(1e300), hi(-1e300);
  for (const glm::dvec2& v : poly) {
    lo = glm::min(lo, v);
    hi = glm::max(hi, v);
  }
  return p.x >= lo.x - margin && p.x <= hi.x + margin && p.y >= lo.y - margin &&
         p.y <= hi.y + margin;
}

template <size_t N>
double insideDistance(const std::array<glm::dvec2, N>& poly, glm::dvec2 p) {
  double area = 0.0;
  for (size_t i = 0; i < N; ++i) {
    const glm::dvec2 a = poly[i], b = poly[(i + 1) % N];
    area += a.x * b.y - b.x * a.y;
  }
  const double sign = area > 0 ? 1.0 : -1.0;
  double best = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < N; ++i) {
    const glm::dvec2 a = poly[i], b = poly[(i + 1) % N], e = b - a;
    const double cross = e.x * (p.y - a.y) - e.y * (p.x - a.x);
    best = std::min(best, sign * cross / glm::length(e));
  }
  return best;
}

TEST(SoftwareRasterizer, DrawsTheTriangleThatARayThroughEachPixelCentreHitsFirst) {
  SoftwareRasterizer raster;
  for (uint32_t seed = 1; seed <= 5; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const DrawnTriangles d(raster, seed);
    size_t mismatches = 0, unexplained = 0, holes = 0, drawn = 0;
    std::ostringstream examples;
    for (int y = 0; y < d.cam.height; ++y)
      for (int x = 0; x < d.cam.width; ++x) {
        const uint32_t got = d.ids.at(x, y);
        const uint32_t want = d.oracle.first(x + 0.5, y + 0.5).triangle;
        drawn += got != kNoTriangle;
        if (got == want) continue;
        ++mismatches;
        const bool nearEdge =
            edgeNear(d.cam, d.soup, got, x, y, 0.5) || edgeNear(d.cam, d.soup, want, x, y, 0.5);
        const bool tie = got != kNoTriangle && want != kNoHit && d.oracle.depthTie(got, want, x, y);
        const bool hole =
            got == kNoTriangle && want != kNoHit && !edgeNear(d.cam, d.soup, want, x, y, 1.0);
        holes += hole;
        if (hole || (!nearEdge && !tie)) {
          unexplained += !hole;
          if (holes + unexplained <= 5)
            examples << " (" << x << "," << y << ") raster "
                     << int64_t(got == kNoTriangle ? -1 : int64_t(got)) << " ray "
                     << int64_t(want == kNoHit ? -1 : int64_t(want));
        }
      }
    const size_t pixels = size_t(d.cam.width) * size_t(d.cam.height);
    EXPECT_GT(drawn, pixels / 4) << "the soup should cover a good part of the image";
    EXPECT_EQ(holes, 0u) << "empty pixels inside a triangle's interior:" << examples.str();
    EXPECT_EQ(unexplained, 0u) << "mismatches away from edges and depth ties:" << examples.str();
    EXPECT_LT(double(mismatches), 0.005 * double(pixels));

    EXPECT_LT(drawn, pixels) << "the soup should leave some of the image empty";
  }
}

// A convex quad with its corners on the rays through window points `w`, at depths
// `z` (so it need not be planar), split along the diagonal 0-2 or 1-3.
FlatTriangles quadThrough(const Camera& cam, const std::array<glm::dvec2, 4>& w,
                          const std::array<float, 4>& z, bool otherDiagonal) {
  std::array<glm::vec3, 4> v;
  for (size_t k = 0; k < 4; ++k) v[k] = onPixelRay(cam, w[k], z[k]);
  FlatTriangles f;
  if (!otherDiagonal) {
    addTriangle(f, v[0], v[1], v[2]);
    addTriangle(f, v[0], v[2], v[3]);
  } else {
    addTriangle(f, v[1], v[2], v[3]);
    addTriangle(f, v[1], v[3], v[0]);
  }
  return f;
}

std::vector<std::array<glm::dvec2, 4>> quadCases() {
  std::vector<std::array<glm::dvec2, 4>> q;
  // Axis-aligned square with corners on pixel centres: every edge, and the slope-1
  // diagonal, runs exactly through pixel centres.
  q.push_back({glm::dvec2{20.5, 10.5}, {100.5, 10.5}, {100.5, 90.5}, {20.5, 90.5}});
  // A diamond whose diagonals are a column and a row of pixel centres.
  q.push_back({glm::dvec2{80.5, 10.5}, {130.5, 60.5}, {80.5, 110.5}, {30.5, 60.5}});
  // Squares at several orientations.
  for (int deg = 5; deg < 90; deg += 10) {
    std::array<glm::dvec2, 4> s;
    for (int k = 0; k < 4; ++k) {
      const double a = (deg + 90.0 * k) * 3.14159265358979 / 180.0;
      s[size_t(k)] = glm::dvec2(80.3, 60.7) + 45.0 * glm::dvec2(std::cos(a), std::sin(a));
    }
    q.push_back(s);
  }
  // Random cyclic (hence convex) quads, some over the image border.
  std::mt19937 rng(42);
  auto U = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  for (int i = 0; i < 8; ++i) {
    std::array<double, 4> a;
    for (double& x : a) x = U(0, 6.283185307);
    std::sort(a.begin(), a.end());
    const glm::dvec2 c(U(0, 160), U(0, 120));
    const double r = U(10, 90);
    std::array<glm::dvec2, 4> s;
    for (size_t k = 0; k < 4; ++k) s[k] = c + r * glm::dvec2(std::cos(a[k]), std::sin(a[k]));
    q.push_back(s);
  }
  return q;
}

TEST(SoftwareRasterizer, DrawsEveryPixelOfAQuadSplitOnADiagonalExactlyOnce) {
  SoftwareRasterizer raster;
  std::mt19937 rng(7);
  auto U = [&](float a, float b) { return std::uniform_real_distribution<float>(a, b)(rng); };
  const std::vector<Camera> cameras = {rasterCamera({0, 0, 0}, 0, 0),
                                       rasterCamera({3, 1.5f, -2}, 37, 12)};
  int caseNo = 0;
  for (const Camera& cam : cameras)
    for (const auto& w : quadCases())
      for (bool otherDiagonal : {false, true})
        for (bool flat : {true, false}) {
          SCOPED_TRACE("case " + std::to_string(caseNo++));
          std::array<float, 4> z;
          for (float& d : z) d = flat ? 8.0f : U(2.0f, 30.0f);
          const FlatTriangles quad = quadThrough(cam, w, z, otherDiagonal);
          std::vector<uint8_t> first, second;
          raster.coverage(cam, quad, std::vector<uint32_t>{0}, 0.0f, first);
          raster.coverage(cam, quad, std::vector<uint32_t>{1}, 0.0f, second);
          size_t twice = 0, gaps = 0, spills = 0, inside = 0;
          for (int y = 0; y < cam.height; ++y)
            for (int x = 0; x < cam.width; ++x) {
              const size_t p = size_t(y) * size_t(cam.width) + size_t(x);
              // Corners are snapped to 1/256 px: centres closer than 0.01 px to the
              // quad's outline are not decided by the exact oracle.
              const double in = insideDistance(w, {x + 0.5, y + 0.5});
              twice += first[p] && second[p];
              inside += in > 0.01;
              gaps += in > 0.01 && !first[p] && !second[p];
              spills += in < -0.01 && (first[p] || second[p]);
            }
          EXPECT_EQ(twice, 0u);
          EXPECT_EQ(gaps, 0u);
          EXPECT_EQ(spills, 0u);
          EXPECT_GT(inside, 0u);
        }
}

TEST(SoftwareRasterizer, CoverageWithAnInsetCountsOnlyCentresThatFarInsideATriangle) {
  SoftwareRasterizer raster;
  const Camera cam = rasterCamera({1, 2, 3}, -20, 8);
  std::mt19937 rng(11);
  auto U = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  for (int i = 0; i < 12; ++i) {
    const std::array<glm::dvec2, 3> w = {glm::dvec2{U(-20, 180), U(-20, 140)},
                                         glm::dvec2{U(-20, 180), U(-20, 140)},
                                         glm::dvec2{U(-20, 180), U(-20, 140)}};
    FlatTriangles f;
    addTriangle(f, onPixelRay(cam, w[0], float(U(2, 20))), onPixelRay(cam, w[1], float(U(2, 20))),
                onPixelRay(cam, w[2], float(U(2, 20))));
    for (float inset : {0.0f, 0.25f, 1.0f}) {
      SCOPED_TRACE("triangle " + std::to_string(i) + " inset " + std::to_string(inset));
      std::vector<uint8_t> covered;
      raster.coverage(cam, f, std::vector<uint32_t>{0}, inset, covered);
      size_t wrong = 0, wrongEmpty = 0;
      for (int y = 0; y < cam.height; ++y)
        for (int x = 0; x < cam.width; ++x) {
          const double in = insideDistance(w, {x + 0.5, y + 0.5});
          if (std::abs(in - inset) < 0.01) continue;  // within the snapping of the corners
          wrong += (covered[size_t(y) * size_t(cam.width) + size_t(x)] == kCovered) != (in > inset);
          // Called certainly empty only outside the triangle grown by the
          // inset (the growth is mitred at the corners, so some pixels farther
          // out may be left undecided, which is safe).
          if (inset > 0.0f && std::abs(in + inset) >= 0.01 &&
              covered[size_t(y) * size_t(cam.width) + size_t(x)] == kUncovered && in >= -inset &&
              withinBounds(w, {x + 0.5, y + 0.5}, 8.0 * inset))
            ++wrongEmpty;
        }
      EXPECT_EQ(wrong, 0u);
      EXPECT_EQ(wrongEmpty, 0u);
    }
  }
}

TEST(SoftwareRasterizer, CoverageWithAnInsetIsASubsetOfWhatDrawFills) {
  SoftwareRasterizer raster;
  for (uint32_t seed = 11; seed <= 13; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const DrawnTriangles d(raster, seed);
    std::vector<uint8_t> covered;
    raster.coverage(d.cam, d.soup, allOf(d.soup), 0.25f, covered);
    size_t inset = 0, notDrawn = 0, noRayHit = 0;
    for (int y = 0; y < d.cam.height; ++y)
      for (int x = 0; x < d.cam.width; ++x) {
        if (covered[size_t(y) * size_t(d.cam.width) + size_t(x)] != kCovered) continue;
        ++inset;
        notDrawn += d.ids.at(x, y) == kNoTriangle;
        noRayHit += !d.oracle.first(x + 0.5, y + 0.5).valid();
      }
    EXPECT_EQ(notDrawn, 0u);
    EXPECT_EQ(noRayHit, 0u);
    EXPECT_GT(inset, size_t(d.cam.width * d.cam.height) / 5);
  }
}

TEST(SoftwareRasterizer, DrawsAQuadFarFromTheOriginLikeTheExactProjection) {
  // Window corners and depths of the quad; the same at the origin and 100 km away.
  const std::array<glm::dvec2, 4> w = {
      glm::dvec2{30.3, 20.7}, {130.6, 25.2}, {120.1, 100.4}, {40.8, 90.9}};
  const std::array<float, 4> z = {30.0f, 34.0f, 40.0f, 36.0f};
  SoftwareRasterizer raster;
  size_t countAt[2] = {0, 0};
  size_t band = 0;
  for (int far = 0; far < 2; ++far) {
    SCOPED_TRACE(far ? "at x = 1e5" : "at the origin");
    const Camera cam = rasterCamera({far ? 1.0e5f : 0.0f, 1.7f, 0.0f}, 30.0f, 5.0f);
    const FlatTriangles quad = quadThrough(cam, w, z, false);
    IdBuffer ids;
    raster.draw(cam, quad, allOf(quad), ids);
    // A vertex 1e5 m out is off by a few float ulps (7.8 mm each) through its
    // rounding and the view matrix; 4 ulps at 30 m, where a pixel is 0.29 m, is
    // 0.11 px. Centres closer than that to the outline are not decided.
    const double pixelAtNearest =
        2.0 * std::tan(0.5 * glm::radians(double(cam.vfovDeg))) * 30.0 / cam.height;
    const double tolerance = far ? 4.0 * 0.0078125 / pixelAtNearest + 0.01 : 0.01;
    size_t wrong = 0;
    double worst = 0.0;  // px from the outline, of the farthest wrong centre
    band = 0;
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const double in = insideDistance(w, {x + 0.5, y + 0.5});
        const bool drawn = ids.at(x, y) != kNoTriangle;
        countAt[far] += drawn;
        if (std::abs(in) < tolerance) {
          ++band;
          continue;
        }
        if (drawn != (in > 0)) {
          ++wrong;
          worst = std::max(worst, std::abs(in));
        }
      }
    EXPECT_EQ(wrong, 0u) << "centres up to " << worst
                         << " px from the outline on the wrong side (tolerance " << tolerance
                         << " px)";
  }
  EXPECT_LE(std::max(countAt[0], countAt[1]) - std::min(countAt[0], countAt[1]), band);
  EXPECT_GT(countAt[0], 5000u);
}

TEST(SoftwareRasterizer, DrawsNothingForTrianglesBehindTheCamera) {
  const Camera cam = rasterCamera({2, 1, -4}, 60, -10);
  std::mt19937 rng(5);
  auto U = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  FlatTriangles behind;
  for (int i = 0; i < 200; ++i) {
    // Behind the eye; mirrored through it, many would cover the whole image.
    const double spread = i % 4 == 0 ? 2000 : 100;
    std::array<glm::vec3, 3> v;
    for (auto& p : v)
      p = onPixelRay(cam, {U(-spread, 160 + spread), U(-spread, 120 + spread)},
                     float(U(-30, -0.01)));
    addTriangle(behind, v[0], v[1], v[2]);
  }
  SoftwareRasterizer raster;
  IdBuffer ids;
  const RasterStats stats = raster.draw(cam, behind, allOf(behind), ids);
  EXPECT_EQ(std::count(ids.ids.begin(), ids.ids.end(), kNoTriangle), int64_t(ids.ids.size()));
  EXPECT_EQ(stats.trianglesSetUp, 0u);
  std::vector<uint8_t> covered;
  raster.coverage(cam, behind, allOf(behind), 0.0f, covered);
  EXPECT_EQ(std::count(covered.begin(), covered.end(), uint8_t(1)), 0);
}

TEST(SoftwareRasterizer, DrawsThePixelsARayCastSeesOfATriangleCrossingTheNearPlane) {
  const Camera cam = rasterCamera({-1, 3, 2}, 15, 20);
  // Corners: window point and view depth; one or two corners behind the eye.
  struct Corner {
    glm::dvec2 w;
    float z;
  };
  const std::vector<std::array<Corner, 3>> cases = {
      {Corner{{80, 60}, -3.0f}, Corner{{20, 100}, 10.0f}, Corner{{150, 90}, 12.0f}},
      {Corner{{40, 30}, -0.5f}, Corner{{100, 20}, -2.0f}, Corner{{90, 100}, 6.0f}},
      {Corner{{-50, 60}, 0.05f}, Corner{{200, 50}, 0.3f}, Corner{{80, 130}, 1.0f}},
      {Corner{{80, 60}, -20.0f}, Corner{{81, 61}, 20.0f}, Corner{{79, 64}, 20.0f}},
  };
  SoftwareRasterizer raster;
  for (size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE("case " + std::to_string(i));
    FlatTriangles f;
    addTriangle(f, onPixelRay(cam, cases[i][0].w, cases[i][0].z),
                onPixelRay(cam, cases[i][1].w, cases[i][1].z),
                onPixelRay(cam, cases[i][2].w, cases[i][2].z));
    const DrawnTriangles d(raster, cam, std::move(f));
    size_t seen = 0, wrong = 0;
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const bool hit = d.oracle.first(x + 0.5, y + 0.5).valid();
        seen += hit;
        if (hit != (d.ids.at(x, y) == 0u) && !edgeNear(cam, d.soup, 0, x, y, 0.5)) ++wrong;
      }
    EXPECT_EQ(wrong, 0u);
    EXPECT_GT(seen, 100u) << "the case should show a good part of the triangle";
  }
}

// The oracle for the hierarchical depth and the nearest-first order: each
// triangle drawn alone (nothing can hide it then), and per pixel the one
// with the largest 1/w, ties going to the earlier in the order given.
IdBuffer nearestOfEachAlone(SoftwareRasterizer& raster, const Camera& cam,
                            const FlatTriangles& soup, const std::vector<uint32_t>& which) {
  IdBuffer best;
  best.reset(cam.width, cam.height);
  IdBuffer alone;
  for (uint32_t t : which) {
    const uint32_t one[] = {t};
    raster.draw(cam, soup, one, alone);
    for (size_t p = 0; p < alone.ids.size(); ++p)
      if (alone.ids[p] != kNoTriangle && alone.inverseDepth[p] > best.inverseDepth[p]) {
        best.inverseDepth[p] = alone.inverseDepth[p];
        best.ids[p] = alone.ids[p];
      }
  }
  return best;
}

TEST(SoftwareRasterizer, DrawsEachPixelAsTheNearestOfItsTrianglesDrawnAloneInAnyOrder) {
  SoftwareRasterizer raster;
  for (uint32_t seed = 1; seed <= 6; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    Camera cam = randomCamera(seed);
    if (seed > 4) {  // a width that is no multiple of the 32-column tiles, a last band cut short
      cam.width = 150;
      cam.height = 100;
    }
    FlatTriangles soup = randomSoup(cam, seed, 300);
    // Hard cases for the order: exact duplicates (equal depths everywhere),
    // and a near wall over the whole image with copies of the soup behind it
    // (wholly hidden, so whole bands are skipped).
    // The duplicated triangles are every 7th of those that win a pixel on
    // their own, so that ties are part of the test whatever the frame size.
    const size_t n = soup.size();
    const IdBuffer alone = nearestOfEachAlone(raster, cam, soup, allOf(soup));
    std::vector<uint32_t> winners;
    for (uint32_t id : alone.ids)
      if (id != kNoTriangle) winners.push_back(id);
    std::sort(winners.begin(), winners.end());
    winners.erase(std::unique(winners.begin(), winners.end()), winners.end());
    std::vector<uint8_t> duplicated(n, 0);
    for (size_t i = 0; i < winners.size(); i += 7) {
      const uint32_t t = winners[i];
      duplicated[t] = 1;
      addTriangle(soup, soup.vertex(t, 0), soup.vertex(t, 1), soup.vertex(t, 2));
    }
    FlatTriangles walled = soup;
    const std::array<glm::dvec2, 4> corners = {glm::dvec2{-10, -10}, glm::dvec2{170, -10},
                                               glm::dvec2{170, 130}, glm::dvec2{-10, 130}};
    addTriangle(walled, onPixelRay(cam, corners[0], 0.5f), onPixelRay(cam, corners[1], 0.5f),
                onPixelRay(cam, corners[2], 0.5f));
    addTriangle(walled, onPixelRay(cam, corners[0], 0.5f), onPixelRay(cam, corners[2], 0.5f),
                onPixelRay(cam, corners[3], 0.5f));
    for (const FlatTriangles* f : {&soup, &walled}) {
      std::vector<uint32_t> forward = allOf(*f), backward(forward.rbegin(), forward.rend());
      for (const std::vector<uint32_t>* which : {&forward, &backward}) {
        IdBuffer together;
        const RasterStats stats = raster.draw(cam, *f, *which, together);
        const IdBuffer want = nearestOfEachAlone(raster, cam, *f, *which);
        size_t wrongIds = 0, wrongDepths = 0, ties = 0, wall = 0;
        for (size_t p = 0; p < want.ids.size(); ++p) {
          wrongIds += together.ids[p] != want.ids[p];
          wrongDepths += together.inverseDepth[p] != want.inverseDepth[p];
          const uint32_t id = want.ids[p];
          ties += id != kNoTriangle && id < soup.size() && (id >= n || duplicated[id]);
          wall += id != kNoTriangle && id >= soup.size();
        }
        EXPECT_EQ(wrongIds, 0u);
        EXPECT_EQ(wrongDepths, 0u);
        if (f == &walled) {
          // The wall hides much of the image (triangles crossing the near
          // plane may come before it), and most of the soup's bands are skipped.
          EXPECT_GT(wall, want.ids.size() / 4);
          EXPECT_GT(stats.bandsSkipped, stats.trianglesSetUp / 2);
        } else {
          EXPECT_GT(ties, 0u) << "duplicates that win pixels should be part of the test";
        }
      }
    }
  }
}

// Coverage with an inset skips hidden triangles as the id buffer does: the
// opacity of a soup behind a near wall is, pixel for pixel, what its
// triangles give one at a time (kCovered where any covers the centre,
// kUncovered where none reaches it), and whole bands are skipped.
TEST(SoftwareRasterizer, CoverageWithAnInsetIsTheUnionOfEachTriangleAloneWhateverItSkips) {
  SoftwareRasterizer raster;
  for (uint32_t seed = 1; seed <= 3; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    Camera cam = randomCamera(seed);
    cam.width = 150;  // no multiple of the 32-column tiles
    cam.height = 100;
    FlatTriangles soup = randomSoup(cam, seed, 200);
    const std::array<glm::dvec2, 4> corners = {glm::dvec2{-10, -10}, glm::dvec2{160, -10},
                                               glm::dvec2{160, 110}, glm::dvec2{-10, 110}};
    addTriangle(soup, onPixelRay(cam, corners[0], 0.5f), onPixelRay(cam, corners[1], 0.5f),
                onPixelRay(cam, corners[2], 0.5f));
    addTriangle(soup, onPixelRay(cam, corners[0], 0.5f), onPixelRay(cam, corners[2], 0.5f),
                onPixelRay(cam, corners[3], 0.5f));
    for (float inset : {0.0f, 0.5f}) {
      SCOPED_TRACE("inset " + std::to_string(inset));
      const std::vector<uint32_t> which = allOf(soup);
      std::vector<uint8_t> together;
      const RasterStats stats = raster.coverage(cam, soup, which, inset, together);
      std::vector<uint8_t> anyCovered(together.size(), 0), anyReaching(together.size(), 0);
      for (uint32_t t : which) {
        std::vector<uint8_t> alone;
        raster.coverage(cam, soup, std::vector<uint32_t>{t}, inset, alone);
        for (size_t p = 0; p < alone.size(); ++p) {
          anyCovered[p] |= alone[p] == kCovered;
          anyReaching[p] |= alone[p] != kUncovered;
        }
      }
      size_t wrong = 0, covered = 0;
      for (size_t p = 0; p < together.size(); ++p) {
        const uint8_t want = anyCovered[p] ? kCovered : anyReaching[p] ? kBeyond : kUncovered;
        wrong += together[p] != want;
        covered += want == kCovered;
      }
      EXPECT_EQ(wrong, 0u);
      EXPECT_GT(covered, together.size() / 2) << "the wall covers most of the image";
      if (inset > 0.0f) {
        EXPECT_GT(stats.bandsSkipped, 0u) << "hidden triangles were skipped";
      }
    }
  }
}

}  // namespace
}  // namespace vistream
