// BruteForceRayQuery: the oracle every other back end is checked against.
// Every query tests every non-degenerate triangle with the double-precision
// watertight test of triangle_intersect.h, so its answers are exact up to
// double rounding and its seams are closed. O(triangles) per ray: meant for
// tests and same-run benchmark baselines, never for production.
#include <algorithm>
#include <cmath>

#include "common/raycast/ray_query.h"
#include "common/raycast/triangle_intersect.h"

namespace vistream {
namespace {

class BruteForceRayQuery final : public RayQuery {
 public:
  explicit BruteForceRayQuery(const FlatTriangles& triangles) : triangles_(triangles) {}

  Hit firstHit(const Ray& ray) const override {
    Hit best;
    if (!isTraceable(ray)) return best;
    double bestT = std::numeric_limits<double>::infinity();
    std::optional<TriangleHit> bestHit;
    forEachHit(ray, [&](uint32_t tri, const TriangleHit& h) {
      // Strictly nearer only: triangles come in index order, so a tie keeps
      // the smaller index.
      if (h.t < bestT) {
        bestT = h.t;
        bestHit = h;
        best.triangle = tri;
      }
      return true;
    });
    if (bestHit) fill(best.triangle, *bestHit, best);
    return best;
  }

  bool occluded(const Ray& ray) const override {
    if (!isTraceable(ray)) return false;
    bool any = false;
    forEachHit(ray, [&](uint32_t, const TriangleHit&) {
      any = true;
      return false;
    });
    return any;
  }

  void allHits(const Ray& ray, std::vector<Hit>& hits) const override {
    hits.clear();
    if (!isTraceable(ray)) return;
    forEachHit(ray, [&](uint32_t tri, const TriangleHit& h) {
      Hit& out = hits.emplace_back();
      fill(tri, h, out);
      return true;
    });
    // Sorted on the reported (float) t so the order is the one a caller sees.
    std::sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) {
      return a.t != b.t ? a.t < b.t : a.triangle < b.triangle;
    });
  }

  const char* name() const override { return "bruteforce"; }

 private:
  // Calls visit(triangle, hit) for every non-degenerate triangle hit in
  // [tnear, tfar], in index order, until visit returns false.
  template <typename Visit>
  void forEachHit(const Ray& ray, Visit&& visit) const {
    const glm::dvec3 org(ray.org), dir(ray.dir);
    const size_t n = triangles_.size();
    for (size_t i = 0; i < n; ++i) {
      if (triangles_.degenerate[i]) continue;
      const std::optional<TriangleHit> h = intersectWatertight(
          org, dir, ray.tnear, ray.tfar, glm::dvec3(triangles_.positions[3 * i]),
          glm::dvec3(triangles_.positions[3 * i + 1]), glm::dvec3(triangles_.positions[3 * i + 2]));
      if (h && !visit(uint32_t(i), *h)) return;
    }
  }

  void fill(uint32_t tri, const TriangleHit& h, Hit& out) const {
    const glm::vec3 a = triangles_.vertex(tri, 0), b = triangles_.vertex(tri, 1),
                    c = triangles_.vertex(tri, 2);
    out.triangle = tri;
    // double t in [tnear, tfar] rounds to a float in [tnear, tfar]: both are floats.
    out.t = float(h.t);
    out.u = float(h.u);
    out.v = float(h.v);
    out.normal = glm::cross(b - a, c - a);
  }

  const FlatTriangles& triangles_;
};

}  // namespace

std::unique_ptr<RayQuery> makeBruteForceRayQuery(const FlatTriangles& triangles) {
  return std::make_unique<BruteForceRayQuery>(triangles);
}

}  // namespace vistream
