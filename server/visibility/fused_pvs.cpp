// Wonka, Wimmer and Schmalstieg 2000 (occluder shrinking, point sampling and
// a conservative occlusion map per sample), with a cube map instead of their
// 2.5D cull map so that it works for any scene. See fused_pvs.h.
#include "server/visibility/fused_pvs.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/core/timer.h"
#include "common/spatial/convex_hull.h"

namespace vistream {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// The parameter t at which the ray p + t*d, t > 0, enters the open convex
// region, or +infinity if it misses the interior.
double rayEntry(const std::vector<glm::dvec4>& planes, const glm::dvec3& p, const glm::dvec3& d) {
  double t0 = 0.0, t1 = kInfinity;
  for (const glm::dvec4& pl : planes) {
    const glm::dvec3 n(pl);
    const double num = pl.w - glm::dot(n, p);  // > 0: p inside this half-space
    const double den = glm::dot(n, d);
    if (den == 0.0) {
      if (num <= 0.0) return kInfinity;
      continue;
    }
    const double t = num / den;
    if (den > 0.0)
      t1 = std::min(t1, t);
    else
      t0 = std::max(t0, t);
    if (!(t0 < t1)) return kInfinity;
  }
  return t0 < t1 ? t0 : kInfinity;
}

// Vertices of {x : dot(n_i, x) <= d_i}: intersections of plane triples that
// satisfy every plane.
std::vector<glm::dvec3> polytopeVertices(const std::vector<glm::dvec4>& planes) {
  std::vector<glm::dvec3> out;
  const size_t n = planes.size();
  for (size_t i = 0; i < n; ++i)
    for (size_t j = i + 1; j < n; ++j)
      for (size_t k = j + 1; k < n; ++k) {
        const glm::dvec3 a(planes[i]), b(planes[j]), c(planes[k]);
        const double det = glm::dot(a, glm::cross(b, c));
        if (std::abs(det) < 1e-12) continue;
        const glm::dvec3 x = (planes[i].w * glm::cross(b, c) + planes[j].w * glm::cross(c, a) +
                              planes[k].w * glm::cross(a, b)) /
                             det;
        bool inside = true;
        for (const glm::dvec4& p : planes)
          if (glm::dot(glm::dvec3(p), x) > p.w + 1e-9 * (1.0 + glm::length(x))) inside = false;
        if (inside) out.push_back(x);
      }
  return out;
}

// Cube-map geometry: face f has major axis a = f/2 and sign + for even f.
// Pixel (i, j) spans u in [-1 + 2i/R, -1 + 2(i+1)/R] along axis (a+1)%3 and v
// likewise along (a+2)%3.
struct CubeFace {
  int a, b, c;
  double sign;
};
CubeFace cubeFace(int f) {
  return {f / 2, (f / 2 + 1) % 3, (f / 2 + 2) % 3, (f & 1) ? -1.0 : 1.0};
}

glm::dvec3 cornerDirection(const CubeFace& cf, int res, int i, int j) {
  glm::dvec3 d;
  d[cf.a] = cf.sign;
  d[cf.b] = -1.0 + 2.0 * double(i) / double(res);
  d[cf.c] = -1.0 + 2.0 * double(j) / double(res);
  return d;
}

// Pixel range on a cube face that the cone of `points` seen from p can touch;
// false if the cone misses the face. Conservative: whole face when the cone
// reaches behind the face's plane.
bool footprint(const std::vector<glm::dvec3>& points, const glm::dvec3& p, const CubeFace& cf,
               int res, glm::ivec4& range, const std::vector<glm::dvec4>* clipPlanes = nullptr) {
  double umin = kInfinity, umax = -kInfinity, vmin = kInfinity, vmax = -kInfinity;
  bool anyFront = false, anyBehind = false;
  for (const glm::dvec3& x : points) {
    const glm::dvec3 d = x - p;
    const double w = cf.sign * d[cf.a];
    if (w <= 0.0) {
      anyBehind = true;
      continue;
    }
    anyFront = true;
    const double u = d[cf.b] / w, v = d[cf.c] / w;
    umin = std::min(umin, u);
    umax = std::max(umax, u);
    vmin = std::min(vmin, v);
    vmax = std::max(vmax, v);
  }
  if (!anyFront) return false;
  if (anyBehind && clipPlanes) {
    // A convex region reaching behind the face's plane: its part in front
    // (w >= a hair) projects to a bounded footprint.
    std::vector<glm::dvec4> planes = *clipPlanes;
    glm::dvec3 n(0.0);
    n[cf.a] = -cf.sign;
    planes.emplace_back(n, glm::dot(n, p) - 1e-6);
    const std::vector<glm::dvec3> clipped = polytopeVertices(planes);
    return !clipped.empty() && footprint(clipped, p, cf, res, range);
  }
  if (anyBehind) {
    range = {0, res - 1, 0, res - 1};
    return true;
  }
  if (umax < -1.0 || umin > 1.0 || vmax < -1.0 || vmin > 1.0) return false;
  auto toPixel = [res](double t) {
    return std::clamp(int(std::floor((t + 1.0) * 0.5 * double(res))), 0, res - 1);
  };
  range = {toPixel(umin), toPixel(umax), toPixel(vmin), toPixel(vmax)};
  return true;
}

// Projected convex outline of points that all lie in front of a cube face
// (counter-clockwise), or empty if one does not.
std::vector<glm::dvec2> projectedHull(const std::vector<glm::dvec3>& points, const glm::dvec3& p,
                                      const CubeFace& cf) {
  std::vector<glm::dvec2> q;
  for (const glm::dvec3& x : points) {
    const glm::dvec3 d = x - p;
    const double w = cf.sign * d[cf.a];
    if (w <= 0.0) return {};
    q.emplace_back(d[cf.b] / w, d[cf.c] / w);
  }
  return convexHull2d(std::move(q));
}

// Can the pixel square [u0,u1] x [v0,v1] overlap the convex outline? False
// only when an outline edge separates them with room to spare (a margin that
// dwarfs rounding), so a "no" is certain.
bool pixelMayOverlap(const std::vector<glm::dvec2>& hull, double u0, double u1, double v0,
                     double v1) {
  if (hull.size() < 3) return true;
  const double margin = 1e-9;
  for (size_t i = 0; i < hull.size(); ++i) {
    const glm::dvec2 a = hull[i], b = hull[(i + 1) % hull.size()];
    const glm::dvec2 n(b.y - a.y, a.x - b.x);  // outward for a counter-clockwise outline
    const double limit = glm::dot(n, a) + margin * glm::length(n);
    const double nearest =
        std::min({glm::dot(n, glm::dvec2(u0, v0)), glm::dot(n, glm::dvec2(u1, v0)),
                  glm::dot(n, glm::dvec2(u0, v1)), glm::dot(n, glm::dvec2(u1, v1))});
    if (nearest > limit) return false;
  }
  return true;
}

// Distance from p to the nearest point of a box: a lower bound of the
// distance to anything inside it.
double distanceToBox(const glm::dvec3& p, const std::vector<glm::dvec3>& pts) {
  glm::dvec3 lo(kInfinity), hi(-kInfinity);
  for (const glm::dvec3& x : pts) {
    lo = glm::min(lo, x);
    hi = glm::max(hi, x);
  }
  const glm::dvec3 d = glm::max(glm::max(lo - p, p - hi), glm::dvec3(0.0));
  return glm::length(d);
}

}  // namespace

FusedPvs::FusedPvs(const EpsilonPvs& base, const FusedPvsOptions& options)
    : base_(base), options_(options) {
  for (const ConvexOccluder& o : base.occluders().occluders) {
    if (o.kind != ConvexOccluder::Kind::Solid) continue;
    ErodedSolid e;
    for (const glm::dvec4& p : o.planes)
      e.planes.emplace_back(glm::dvec3(p), p.w - options.epsilon);
    e.vertices = polytopeVertices(e.planes);
    if (e.vertices.size() >= 4) solids_.push_back(std::move(e));  // thinner than 2 epsilon: gone
  }
}

PvsResult FusedPvs::compute(const Box3f& cell, const PvsOptions& baseOptions,
                            FusedPvsStats* fusedStats) const {
  Stopwatch clock;
  PvsResult result = base_.compute(cell, baseOptions);
  FusedPvsStats st;
  st.erodedOccluders = solids_.size();
  st.candidateFaces = result.faces.size();

  // Samples on the six faces of the cell, spaced epsilon * sqrt(2) so that
  // every boundary point is within epsilon of one.
  std::vector<glm::dvec3> samples;
  const double spacing = options_.epsilon * std::sqrt(2.0);
  const glm::dvec3 lo(cell.lo), hi(cell.hi);
  for (int axis = 0; axis < 3; ++axis) {
    const int b = (axis + 1) % 3, c = (axis + 2) % 3;
    const int nb = std::max(1, int(std::ceil((hi[b] - lo[b]) / spacing))) + 1;
    const int nc = std::max(1, int(std::ceil((hi[c] - lo[c]) / spacing))) + 1;
    for (int side = 0; side < 2; ++side)
      for (int i = 0; i < nb; ++i)
        for (int j = 0; j < nc; ++j) {
          glm::dvec3 s;
          s[axis] = side ? hi[axis] : lo[axis];
          s[b] = lo[b] + (hi[b] - lo[b]) * double(i) / double(nb - 1);
          s[c] = lo[c] + (hi[c] - lo[c]) * double(j) / double(nc - 1);
          samples.push_back(s);
        }
  }
  st.samples = samples.size();

  const int res = options_.resolution;
  std::vector<double> depth(size_t(6) * size_t(res) * size_t(res));
  std::vector<double> cornerEntry(size_t(res + 1) * size_t(res + 1));
  // Longest corner direction of each pixel (directions have major component 1).
  std::vector<double> pixelReach(size_t(res) * size_t(res));
  for (int j = 0; j < res; ++j)
    for (int i = 0; i < res; ++i) {
      double m = 0.0;
      for (int dj = 0; dj < 2; ++dj)
        for (int di = 0; di < 2; ++di)
          m = std::max(m, glm::length(cornerDirection(cubeFace(0), res, i + di, j + dj)));
      pixelReach[size_t(j) * size_t(res) + size_t(i)] = m;
    }
  std::vector<uint8_t> visible(result.faces.size(), 0);
  std::vector<const std::vector<glm::dvec3>*> faceVerts(result.faces.size());
  for (size_t i = 0; i < result.faces.size(); ++i)
    faceVerts[i] = base_.faceVertices(result.faces[i]);
  size_t remaining = result.faces.size();

  for (const glm::dvec3& p : samples) {
    if (remaining == 0) break;
    std::fill(depth.begin(), depth.end(), kInfinity);
    // Draw every eroded occluder: covered pixels keep the smallest bound.
    for (const ErodedSolid& o : solids_) {
      bool inside = true;
      for (const glm::dvec4& pl : o.planes) inside = inside && glm::dot(glm::dvec3(pl), p) < pl.w;
      if (inside) continue;
      for (int f = 0; f < 6; ++f) {
        const CubeFace cf = cubeFace(f);
        glm::ivec4 r;
        if (!footprint(o.vertices, p, cf, res, r, &o.planes)) continue;
        // Entry parameter of each corner ray of the footprint. For a fully
        // covered pixel every plane the sample lies outside of is entered by
        // all its rays, each plane's entry parameter is convex over the
        // pixel, so the largest is at a corner; times the longest corner
        // direction it bounds the entry distance of every ray in the pixel.
        const int w = r.y - r.x + 2;
        for (int j = r.z; j <= r.w + 1; ++j)
          for (int i = r.x; i <= r.y + 1; ++i)
            cornerEntry[size_t(j - r.z) * size_t(w) + size_t(i - r.x)] =
                rayEntry(o.planes, p, cornerDirection(cf, res, i, j));
        double* face = depth.data() + size_t(f) * size_t(res) * size_t(res);
        for (int j = r.z; j <= r.w; ++j)
          for (int i = r.x; i <= r.y; ++i) {
            const size_t c0 = size_t(j - r.z) * size_t(w) + size_t(i - r.x);
            const double t =
                std::max({cornerEntry[c0], cornerEntry[c0 + 1], cornerEntry[c0 + size_t(w)],
                          cornerEntry[c0 + size_t(w) + 1]});
            if (t == kInfinity) continue;
            double& d = face[size_t(j) * size_t(res) + size_t(i)];
            d = std::min(d, t * pixelReach[size_t(j) * size_t(res) + size_t(i)]);
          }
      }
    }
    // Test the faces not yet seen from an earlier sample.
    for (size_t k = 0; k < result.faces.size(); ++k) {
      if (visible[k]) continue;
      const auto* verts = faceVerts[k];
      bool seen = verts == nullptr;
      if (!seen) {
        const double near = distanceToBox(p, *verts);
        for (int f = 0; f < 6 && !seen; ++f) {
          const CubeFace cf = cubeFace(f);
          glm::ivec4 r;
          if (!footprint(*verts, p, cf, res, r)) continue;
          const double* face = depth.data() + size_t(f) * size_t(res) * size_t(res);
          // Pixels of the footprint that the face's outline can reach: a
          // slanted wall does not need the sky pixels of its bounding box.
          const std::vector<glm::dvec2> hull = projectedHull(*verts, p, cf);
          const double px = 2.0 / double(res);
          for (int j = r.z; j <= r.w && !seen; ++j)
            for (int i = r.x; i <= r.y; ++i) {
              if (face[size_t(j) * size_t(res) + size_t(i)] < near) continue;
              if (!hull.empty() && !pixelMayOverlap(hull, -1.0 + px * i, -1.0 + px * (i + 1),
                                                    -1.0 + px * j, -1.0 + px * (j + 1)))
                continue;
              seen = true;
              break;
            }
        }
      }
      if (seen) {
        visible[k] = 1;
        --remaining;
      }
    }
  }

  std::vector<uint32_t> faces;
  for (size_t k = 0; k < result.faces.size(); ++k)
    if (visible[k]) faces.push_back(result.faces[k]);
  st.fusedCulled = result.faces.size() - faces.size();
  result.stats.facesOccluded += st.fusedCulled;
  result.faces = std::move(faces);
  // Objects still holding a face.
  std::vector<uint32_t> objects;
  const Scene& scene = base_.scene();
  for (uint32_t o : result.objects) {
    for (uint32_t f : scene.objects[o].mesh.faceIds)
      if (std::binary_search(result.faces.begin(), result.faces.end(), f)) {
        objects.push_back(o);
        break;
      }
  }
  result.objects = std::move(objects);
  st.timeMs = clock.ms();
  result.stats.timeMs = st.timeMs;
  if (fusedStats) *fusedStats = st;
  return result;
}

}  // namespace vistream
