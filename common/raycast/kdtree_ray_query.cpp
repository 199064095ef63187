// RayQuery back end on the project's own kD-tree (common/spatial/kdtree.h):
// a triangle kD-tree with split clipping, traversed front to back along the
// ray (the recursive ray traversal of Havran's PhD thesis, 2000, in its stack
// form), with triangles tested by the same double-precision watertight test
// as the brute-force oracle, so both decide seams alike.
//
// Leaves share their boundary planes and a triangle may be referenced by
// several leaves, so:
//  - firstHit keeps the nearest hit over all leaves visited and only skips a
//    leaf when it is entered beyond that hit plus a relative 1e-5 margin (the
//    margin covers the float rounding of leaf entry distances, about 1e-6
//    relative). A hit exactly on a leaf boundary therefore still meets the
//    triangles of the next leaf, and equal-t ties resolve to the smaller
//    triangle index as the interface requires.
//  - allHits collects every hit of every leaf and removes repeats.
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include "common/raycast/ray_query.h"
#include "common/raycast/triangle_intersect.h"
#include "common/spatial/kdtree.h"

namespace vistream {

namespace {

// Relative margin beyond the nearest hit within which leaves are still
// visited; see the file comment.
constexpr double kPruneMargin = 1e-5;

class KdTreeRayQuery final : public RayQuery {
 public:
  explicit KdTreeRayQuery(const FlatTriangles& triangles)
      : triangles_(triangles), tree_(buildTree(triangles)) {}

  Hit firstHit(const Ray& ray) const override {
    const glm::dvec3 org(ray.org), dir(ray.dir);
    uint32_t best = kNoHit;
    TriangleHit bestHit{std::numeric_limits<double>::infinity(), 0.0, 0.0};
    tree_.traverseRay(
        ray.org, ray.dir, ray.tnear, ray.tfar, [&](int32_t leaf, float, float) -> float {
          for (const uint32_t tri : tree_.items(leaf)) {
            const std::optional<TriangleHit> h = intersect(org, dir, ray, tri);
            if (h && (h->t < bestHit.t || (h->t == bestHit.t && tri < best))) {
              bestHit = *h;
              best = tri;
            }
          }
          if (best == kNoHit) return ray.tfar;
          const double limit = bestHit.t + kPruneMargin * std::abs(bestHit.t);
          return float(limit) < limit
                     ? std::nextafter(float(limit), std::numeric_limits<float>::infinity())
                     : float(limit);
        });
    return best == kNoHit ? Hit{} : makeHit(best, bestHit);
  }

  bool occluded(const Ray& ray) const override {
    const glm::dvec3 org(ray.org), dir(ray.dir);
    bool hit = false;
    tree_.traverseRay(ray.org, ray.dir, ray.tnear, ray.tfar, [&](int32_t leaf, float, float) {
      for (const uint32_t tri : tree_.items(leaf)) {
        if (intersect(org, dir, ray, tri)) {
          hit = true;
          return false;
        }
      }
      return true;
    });
    return hit;
  }

  void allHits(const Ray& ray, std::vector<Hit>& hits) const override {
    hits.clear();
    const glm::dvec3 org(ray.org), dir(ray.dir);
    tree_.traverseRay(ray.org, ray.dir, ray.tnear, ray.tfar, [&](int32_t leaf, float, float) {
      for (const uint32_t tri : tree_.items(leaf))
        if (const std::optional<TriangleHit> h = intersect(org, dir, ray, tri))
          hits.push_back(makeHit(tri, *h));
      return true;
    });
    // A triangle referenced by several leaves gives the same hit each time,
    // so after sorting its repeats are neighbours.
    std::sort(hits.begin(), hits.end(), [](const Hit& x, const Hit& y) {
      return x.t < y.t || (x.t == y.t && x.triangle < y.triangle);
    });
    hits.erase(std::unique(hits.begin(), hits.end(),
                           [](const Hit& x, const Hit& y) { return x.triangle == y.triangle; }),
               hits.end());
  }

  const char* name() const override { return "kdtree"; }

 private:
  const FlatTriangles& triangles_;
  KdTree tree_;

  // Degenerate triangles are never hit, so they get an empty box and stay out
  // of the tree altogether.
  static KdTree buildTree(const FlatTriangles& triangles) {
    std::vector<Box3f> bounds(triangles.size());
    for (size_t t = 0; t < triangles.size(); ++t) {
      if (t < triangles.degenerate.size() && triangles.degenerate[t]) continue;
      for (int k = 0; k < 3; ++k) bounds[t].extend(triangles.vertex(t, k));
    }
    return KdTree::build(bounds, kRayCastingKdOptions, [&triangles](uint32_t t, const Box3f& box) {
      return clippedTriangleBounds(triangles.vertex(t, 0), triangles.vertex(t, 1),
                                   triangles.vertex(t, 2), box);
    });
  }

  std::optional<TriangleHit> intersect(const glm::dvec3& org, const glm::dvec3& dir, const Ray& ray,
                                       uint32_t tri) const {
    return intersectWatertight(org, dir, ray.tnear, ray.tfar, glm::dvec3(triangles_.vertex(tri, 0)),
                               glm::dvec3(triangles_.vertex(tri, 1)),
                               glm::dvec3(triangles_.vertex(tri, 2)));
  }

  Hit makeHit(uint32_t tri, const TriangleHit& h) const {
    const glm::vec3 a = triangles_.vertex(tri, 0), b = triangles_.vertex(tri, 1),
                    c = triangles_.vertex(tri, 2);
    Hit hit;
    hit.triangle = tri;
    hit.t = float(h.t);
    hit.u = float(h.u);
    hit.v = float(h.v);
    hit.normal = glm::cross(b - a, c - a);
    return hit;
  }
};

}  // namespace

std::unique_ptr<RayQuery> makeKdTreeRayQuery(const FlatTriangles& triangles) {
  return std::make_unique<KdTreeRayQuery>(triangles);
}

}  // namespace vistream
