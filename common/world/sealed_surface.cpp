#include "common/world/sealed_surface.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "common/world/solids.h"

namespace vistream {
namespace {

class SealedRayQuery final : public RayQuery {
 public:
  SealedRayQuery(const FlatTriangles& original, double tol)
      : original_(original),
        pieces_(std::make_unique<FlatTriangles>(weldedSurface(original, tol, originalOf_))),
        inner_(makeEmbreeRayQuery(*pieces_)) {}

  Hit firstHit(const Ray& ray) const override { return remap(ray, inner_->firstHit(ray)); }
  bool occluded(const Ray& ray) const override { return inner_->occluded(ray); }

  void allHits(const Ray& ray, std::vector<Hit>& hits) const override {
    thread_local std::vector<Hit> pieceHits;
    pieceHits.clear();
    inner_->allHits(ray, pieceHits);
    hits.clear();
    for (const Hit& h : pieceHits) hits.push_back(remap(ray, h));
    // One hit per original triangle, the nearest, sorted by t then triangle.
    std::sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) {
      return a.triangle < b.triangle || (a.triangle == b.triangle && a.t < b.t);
    });
    hits.erase(std::unique(hits.begin(), hits.end(),
                           [](const Hit& a, const Hit& b) { return a.triangle == b.triangle; }),
               hits.end());
    std::sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) {
      return a.t < b.t || (a.t == b.t && a.triangle < b.triangle);
    });
  }

  void firstHits(std::span<const Ray> rays, std::span<Hit> hits) const override {
    inner_->firstHits(rays, hits);
    for (size_t i = 0; i < rays.size(); ++i) hits[i] = remap(rays[i], hits[i]);
  }
  void occludedMany(std::span<const Ray> rays, std::span<uint8_t> occluded) const override {
    inner_->occludedMany(rays, occluded);
  }

  const char* name() const override { return "embree-sealed"; }

 private:
  // The piece's hit as a hit on its original triangle: barycentrics of the
  // hit point there (clamped into the triangle), and its normal.
  Hit remap(const Ray& ray, Hit h) const {
    if (!h.valid()) return h;
    const uint32_t t = originalOf_[h.triangle];
    const glm::dvec3 a(original_.vertex(t, 0)), b(original_.vertex(t, 1)),
        c(original_.vertex(t, 2));
    const glm::dvec3 e1 = b - a, e2 = c - a, n = glm::cross(e1, e2);
    const double nn = glm::dot(n, n);
    const glm::dvec3 w = glm::dvec3(ray.org) + glm::dvec3(ray.dir) * double(h.t) - a;
    double u = nn > 0.0 ? glm::dot(glm::cross(w, e2), n) / nn : 0.0;
    double v = nn > 0.0 ? glm::dot(glm::cross(e1, w), n) / nn : 0.0;
    u = std::clamp(u, 0.0, 1.0);
    v = std::clamp(v, 0.0, 1.0 - u);
    // Within the ray query's tie window (sampled_visibility.h) of a side,
    // the hit lies on that side: a sliver's edge is then an edge however
    // thin the sliver (barycentrics alone scale with its width).
    const double window = 1e-5 * std::max(double(h.t), 1e-3);
    const double area2 = std::sqrt(nn);
    if (area2 > 0.0) {
      if (u * area2 / glm::length(e2) <= window) u = 0.0;
      if (v * area2 / glm::length(e1) <= window) v = 0.0;
      const double w0 = 1.0 - u - v;
      if (w0 * area2 / glm::length(c - b) <= window && u + v > 0.0) {
        const double s = 1.0 / (u + v);
        u *= s;
        v *= s;
      }
    }
    h.triangle = t;
    h.u = float(u);
    h.v = float(v);
    h.normal = glm::vec3(n);
    return h;
  }

  const FlatTriangles& original_;
  std::vector<uint32_t> originalOf_;
  std::unique_ptr<FlatTriangles> pieces_;
  std::unique_ptr<RayQuery> inner_;
};

}  // namespace

std::unique_ptr<RayQuery> makeSealedRayQuery(const FlatTriangles& triangles, double weldTolerance) {
  return std::make_unique<SealedRayQuery>(triangles, weldTolerance);
}

}  // namespace vistream
