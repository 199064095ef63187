#include "server/visibility/occluders.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <numeric>
#include <unordered_map>

#include "common/core/timer.h"
#include "common/spatial/convex_hull.h"

namespace vistream {
namespace {

struct VertexKey {
  float x, y, z;
  bool operator==(const VertexKey& o) const { return x == o.x && y == o.y && z == o.z; }
};
struct VertexKeyHash {
  size_t operator()(const VertexKey& k) const {
    uint32_t a, b, c;
    std::memcpy(&a, &k.x, 4);
    std::memcpy(&b, &k.y, 4);
    std::memcpy(&c, &k.z, 4);
    return (size_t(a) * 73856093u) ^ (size_t(b) * 19349663u) ^ (size_t(c) * 83492791u);
  }
};

// An object's triangles with vertices welded by exact position.
struct WeldedMesh {
  std::vector<glm::dvec3> vertices;
  std::vector<glm::uvec3> triangles;  // only non-degenerate ones
  std::vector<uint32_t> faceIds;
};

WeldedMesh weld(const Object& o) {
  WeldedMesh m;
  std::unordered_map<VertexKey, uint32_t, VertexKeyHash> index;
  std::vector<uint32_t> remap(o.mesh.positions.size());
  for (size_t i = 0; i < o.mesh.positions.size(); ++i) {
    const glm::vec3 p = o.mesh.positions[i];
    auto [it, inserted] = index.try_emplace(VertexKey{p.x, p.y, p.z}, uint32_t(m.vertices.size()));
    if (inserted) m.vertices.emplace_back(p);
    remap[i] = it->second;
  }
  for (size_t t = 0; t < o.mesh.triangles.size(); ++t) {
    const glm::uvec3 tri = o.mesh.triangles[t];
    const glm::uvec3 w(remap[tri.x], remap[tri.y], remap[tri.z]);
    if (w.x == w.y || w.y == w.z || w.x == w.z) continue;
    if (isDegenerateTriangle(o.mesh.positions[tri.x], o.mesh.positions[tri.y],
                             o.mesh.positions[tri.z]))
      continue;
    m.triangles.push_back(w);
    m.faceIds.push_back(o.mesh.faceIds[t]);
  }
  return m;
}

glm::dvec3 unitNormal(const WeldedMesh& m, const glm::uvec3& t) {
  const glm::dvec3 n =
      glm::cross(m.vertices[t.y] - m.vertices[t.x], m.vertices[t.z] - m.vertices[t.x]);
  return n / glm::length(n);
}

double triangleArea(const WeldedMesh& m, const glm::uvec3& t) {
  return 0.5 * glm::length(glm::cross(m.vertices[t.y] - m.vertices[t.x],
                                      m.vertices[t.z] - m.vertices[t.x]));
}

// Edge-connected components (over welded vertices) of a set of triangles.
std::vector<std::vector<uint32_t>> components(const WeldedMesh& m,
                                              const std::vector<uint32_t>& tris) {
  std::vector<uint32_t> parent(tris.size());
  std::iota(parent.begin(), parent.end(), 0u);
  auto find = [&](uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::map<std::pair<uint32_t, uint32_t>, uint32_t> firstOwner;
  for (uint32_t i = 0; i < tris.size(); ++i) {
    const glm::uvec3 t = m.triangles[tris[i]];
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = t[e], b = t[(e + 1) % 3];
      const auto key = std::minmax(a, b);
      auto [it, inserted] = firstOwner.try_emplace({key.first, key.second}, i);
      if (!inserted) parent[find(i)] = find(it->second);
    }
  }
  std::map<uint32_t, std::vector<uint32_t>> groups;
  for (uint32_t i = 0; i < tris.size(); ++i) groups[find(i)].push_back(tris[i]);
  std::vector<std::vector<uint32_t>> out;
  for (auto& [root, g] : groups) out.push_back(std::move(g));
  return out;
}

// Closed and consistently oriented: every directed edge appears once and its
// reverse once.
bool closedManifold(const WeldedMesh& m, const std::vector<uint32_t>& tris) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (uint32_t ti : tris) {
    const glm::uvec3 t = m.triangles[ti];
    for (int e = 0; e < 3; ++e)
      if (++directed[{t[e], t[(e + 1) % 3]}] > 1) return false;
  }
  for (const auto& [edge, count] : directed)
    if (!directed.count({edge.second, edge.first})) return false;
  return true;
}

double magnitudeOf(const WeldedMesh& m, const std::vector<uint32_t>& tris) {
  double mag = 0.0;
  for (uint32_t ti : tris)
    for (int k = 0; k < 3; ++k) {
      const glm::dvec3 v = glm::abs(m.vertices[m.triangles[ti][k]]);
      mag = std::max({mag, v.x, v.y, v.z});
    }
  return mag;
}

// Tries to make a solid occluder of a closed component; false if not convex.
bool makeSolid(const WeldedMesh& m, const std::vector<uint32_t>& tris, uint32_t object,
               double tolerance, ConvexOccluder& out) {
  if (tris.size() < 4 || !closedManifold(m, tris)) return false;
  std::vector<uint32_t> verts;
  for (uint32_t ti : tris)
    for (int k = 0; k < 3; ++k) verts.push_back(m.triangles[ti][k]);
  std::sort(verts.begin(), verts.end());
  verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
  glm::dvec3 centroid(0.0);
  for (uint32_t v : verts) centroid += m.vertices[v];
  centroid /= double(verts.size());
  // Orientation from the signed volume.
  double volume = 0.0;
  for (uint32_t ti : tris) {
    const glm::uvec3 t = m.triangles[ti];
    volume += glm::dot(m.vertices[t.x] - centroid,
                       glm::cross(m.vertices[t.y] - centroid, m.vertices[t.z] - centroid));
  }
  if (!(std::abs(volume) > 0.0)) return false;
  const double sign = volume > 0.0 ? 1.0 : -1.0;
  const double mag = magnitudeOf(m, tris);
  const double margin = occluderMargin(mag);
  std::vector<glm::dvec4> planes;
  double area = 0.0;
  for (uint32_t ti : tris) {
    const glm::uvec3 t = m.triangles[ti];
    const glm::dvec3 n = sign * unitNormal(m, t);
    area += triangleArea(m, t);
    // Convex: no vertex of the component lies in front of this face's plane.
    const double d0 = glm::dot(n, m.vertices[t.x]);
    for (uint32_t v : verts)
      if (glm::dot(n, m.vertices[v]) - d0 > tolerance * (1.0 + mag)) return false;
    // Innermost vertex of the face, then the margin.
    const double d = std::min({glm::dot(n, m.vertices[t.x]), glm::dot(n, m.vertices[t.y]),
                               glm::dot(n, m.vertices[t.z])}) -
                     margin;
    // Merge with an existing plane of (numerically) the same normal.
    bool merged = false;
    for (glm::dvec4& p : planes)
      if (glm::dot(glm::dvec3(p), n) > 1.0 - 1e-12) {
        p.w = std::min(p.w, d);
        merged = true;
        break;
      }
    if (!merged) planes.emplace_back(n, d);
  }
  // The shrunk region must still hold the centroid, or the margin swallowed it.
  for (const glm::dvec4& p : planes)
    if (!(glm::dot(glm::dvec3(p), centroid) < p.w)) return false;
  out.kind = ConvexOccluder::Kind::Solid;
  out.object = object;
  out.planes = std::move(planes);
  out.area = area;
  out.centre = centroid;
  out.bounds = Box3f{};
  for (uint32_t v : verts) out.bounds.extend(glm::vec3(m.vertices[v]));
  return true;
}

// Makes a polygon occluder of coplanar, edge-connected triangles whose union
// is convex up to float noise. False if the union is not convex.
bool makePolygon(const WeldedMesh& m, const std::vector<uint32_t>& tris, uint32_t object,
                 const glm::dvec3& normal, ConvexOccluder& out) {
  // Boundary loop: directed edges without their reverse.
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  double area = 0.0;
  for (uint32_t ti : tris) {
    const glm::uvec3 t = m.triangles[ti];
    area += triangleArea(m, t);
    for (int e = 0; e < 3; ++e) ++directed[{t[e], t[(e + 1) % 3]}];
  }
  std::map<uint32_t, uint32_t> next;
  for (const auto& [edge, count] : directed) {
    if (count > 1) return false;  // overlapping or non-manifold
    if (directed.count({edge.second, edge.first})) continue;
    if (next.count(edge.first)) return false;  // boundary touches itself
    next[edge.first] = edge.second;
  }
  if (next.size() < 3) return false;
  std::vector<uint32_t> loop;
  for (uint32_t v = next.begin()->first;;) {
    loop.push_back(v);
    const auto it = next.find(v);
    if (it == next.end()) return false;
    v = it->second;
    if (v == loop.front()) break;
    if (loop.size() > next.size()) return false;
  }
  if (loop.size() != next.size()) return false;  // holes or several loops

  // A 2D frame in the plane.
  const glm::dvec3 u =
      glm::normalize(std::abs(normal.x) < 0.9 ? glm::cross(normal, glm::dvec3(1, 0, 0))
                                              : glm::cross(normal, glm::dvec3(0, 1, 0)));
  const glm::dvec3 w = glm::cross(normal, u);
  const glm::dvec3 origin = m.vertices[loop.front()];
  std::vector<glm::dvec2> p2;
  double mag = 0.0;
  double offPlane = 0.0;
  const double d = glm::dot(normal, origin);
  for (uint32_t v : loop) {
    const glm::dvec3 q = m.vertices[v] - origin;
    p2.emplace_back(glm::dot(q, u), glm::dot(q, w));
    const glm::dvec3 a = glm::abs(m.vertices[v]);
    mag = std::max({mag, a.x, a.y, a.z});
    offPlane = std::max(offPlane, std::abs(glm::dot(normal, m.vertices[v]) - d));
  }
  const std::vector<glm::dvec2> hull = convexHull2d(p2);
  if (hull.size() < 3) return false;
  double hullArea = 0.0;
  for (size_t i = 0; i < hull.size(); ++i) {
    const glm::dvec2 a = hull[i], b = hull[(i + 1) % hull.size()];
    hullArea += 0.5 * (a.x * b.y - a.y * b.x);
  }
  // Depth of the deepest notch: loop vertices inside the hull.
  double notch = 0.0;
  for (const glm::dvec2& p : p2) {
    double dist = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < hull.size(); ++i) {
      const glm::dvec2 a = hull[i], b = hull[(i + 1) % hull.size()];
      dist = std::min(dist, cross2(a, b, p) / glm::length(b - a));
    }
    notch = std::max(notch, dist);
  }
  const double margin = occluderMargin(mag);
  // Not convex beyond float noise: a real notch, or a union that covers less
  // than its hull.
  if (notch > 1e-5 * (1.0 + mag) || area < hullArea * (1.0 - 1e-6)) return false;
  const double shrink = notch + margin;
  ConvexOccluder o;
  o.kind = ConvexOccluder::Kind::Polygon;
  o.object = object;
  // The supporting plane; vertices off it by float noise are covered by the
  // slab test in occluderBlocksSegment.
  o.plane = glm::dvec4(normal, d);
  for (size_t i = 0; i < hull.size(); ++i) {
    const glm::dvec2 a = hull[i], b = hull[(i + 1) % hull.size()];
    const glm::dvec2 e = glm::normalize(b - a);
    // Outward normal of a CCW edge in the 2D frame, lifted to 3D.
    const glm::dvec3 n3 = e.y * u - e.x * w;
    const glm::dvec3 a3 = origin + a.x * u + a.y * w;
    o.planes.emplace_back(n3, glm::dot(n3, a3) - shrink);
  }
  o.centre = glm::dvec3(0.0);
  for (uint32_t v : loop) o.centre += m.vertices[v];
  o.centre /= double(loop.size());
  o.area = hullArea;
  o.bounds = Box3f{};
  for (uint32_t v : loop) o.bounds.extend(glm::vec3(m.vertices[v]));
  // Last entry: the slab (normal, half-thickness) holding every vertex.
  o.planes.emplace_back(normal, offPlane + margin);
  out = std::move(o);
  return true;
}

}  // namespace

OccluderSet extractOccluders(const Scene& scene, const OccluderOptions& options) {
  Stopwatch clock;
  OccluderSet set;
  for (uint32_t oi = 0; oi < scene.objects.size(); ++oi) {
    const Object& object = scene.objects[oi];
    if (object.dynamic) continue;
    const WeldedMesh m = weld(object);
    if (m.triangles.empty()) continue;
    std::vector<uint32_t> all(m.triangles.size());
    std::iota(all.begin(), all.end(), 0u);
    std::vector<uint32_t> leftover;
    for (const auto& comp : components(m, all)) {
      ConvexOccluder solid;
      if (options.solids && makeSolid(m, comp, oi, options.coplanarTolerance, solid)) {
        const glm::vec3 e = solid.bounds.extent();
        if (std::max({e.x, e.y, e.z}) < options.minOccluderSize)
          continue;  // a solid part: never an occludee-only polygon either
        set.occluders.push_back(std::move(solid));
        ++set.stats.solids;
      } else {
        leftover.insert(leftover.end(), comp.begin(), comp.end());
      }
    }
    if (!options.polygons || leftover.empty()) continue;
    // Group the remaining triangles by plane, then by edge connectivity.
    const double mag = magnitudeOf(m, leftover);
    const double tol = options.coplanarTolerance * (1.0 + mag);
    std::vector<std::pair<glm::dvec4, std::vector<uint32_t>>> planes;
    for (uint32_t ti : leftover) {
      const glm::dvec3 n = unitNormal(m, m.triangles[ti]);
      const glm::dvec3 c = (m.vertices[m.triangles[ti].x] + m.vertices[m.triangles[ti].y] +
                            m.vertices[m.triangles[ti].z]) /
                           3.0;
      const double d = glm::dot(n, c);
      bool placed = false;
      for (auto& [p, members] : planes)
        if (glm::dot(glm::dvec3(p), n) > 1.0 - 1e-9 && std::abs(p.w - d) < tol) {
          members.push_back(ti);
          placed = true;
          break;
        }
      if (!placed) planes.push_back({glm::dvec4(n, d), {ti}});
    }
    for (const auto& [p, members] : planes) {
      for (const auto& group : components(m, members)) {
        ConvexOccluder poly;
        if (makePolygon(m, group, oi, glm::dvec3(p), poly)) {
          if (poly.area >= options.minPolygonArea &&
              std::sqrt(poly.area) >= options.minOccluderSize) {
            set.stats.mergedPolygons += group.size() > 1;
            ++set.stats.polygons;
            set.occluders.push_back(std::move(poly));
          }
          continue;
        }
        ++set.stats.nonConvexGroups;
        // Fall back to each source face, then to single triangles.
        std::map<uint32_t, std::vector<uint32_t>> byFace;
        for (uint32_t ti : group) byFace[m.faceIds[ti]].push_back(ti);
        for (const auto& [face, faceTris] : byFace) {
          for (const auto& piece : components(m, faceTris)) {
            if (makePolygon(m, piece, oi, glm::dvec3(p), poly)) {
              if (poly.area >= options.minPolygonArea &&
                  std::sqrt(poly.area) >= options.minOccluderSize) {
                ++set.stats.polygons;
                set.occluders.push_back(std::move(poly));
              }
              continue;
            }
            for (uint32_t ti : piece)
              if (makePolygon(m, {ti}, oi, unitNormal(m, m.triangles[ti]), poly) &&
                  poly.area >= options.minPolygonArea &&
                  std::sqrt(poly.area) >= options.minOccluderSize) {
                ++set.stats.polygons;
                set.occluders.push_back(std::move(poly));
              }
          }
        }
      }
    }
  }
  set.stats.timeMs = clock.ms();
  return set;
}

bool occluderBlocksSegment(const ConvexOccluder& o, const glm::dvec3& a, const glm::dvec3& b) {
  if (o.kind == ConvexOccluder::Kind::Solid) {
    double t0 = 0.0, t1 = 1.0;
    for (const glm::dvec4& p : o.planes) {
      const glm::dvec3 n(p);
      const double da = glm::dot(n, a) - p.w, db = glm::dot(n, b) - p.w;
      if (da >= 0.0 && db >= 0.0) return false;
      if (da < 0.0 && db < 0.0) continue;
      const double t = da / (da - db);
      if (da >= 0.0)
        t0 = std::max(t0, t);
      else
        t1 = std::min(t1, t);
      if (!(t0 < t1)) return false;
    }
    return t0 < t1;
  }
  // Polygon: the last plane holds (normal, slab half-thickness h): the
  // triangles lie within h of the supporting plane. The segment must run
  // from strictly one side of that slab to strictly the other, and both of
  // its slab-crossing points must lie strictly inside the shrunk outline. The
  // triangles form a height field over the outline inside the slab, so such a
  // segment cannot avoid them.
  const glm::dvec4 slab = o.planes.back();
  const double h = slab.w;
  const glm::dvec3 n(o.plane);
  const double da = glm::dot(n, a) - o.plane.w, db = glm::dot(n, b) - o.plane.w;
  if (!((da > h && db < -h) || (da < -h && db > h))) return false;
  const double tIn = (da - (da > 0.0 ? h : -h)) / (da - db);
  const double tOut = (da + (da > 0.0 ? h : -h)) / (da - db);
  const glm::dvec3 xIn = a + tIn * (b - a), xOut = a + tOut * (b - a);
  for (size_t i = 0; i + 1 < o.planes.size(); ++i) {
    const glm::dvec4& e = o.planes[i];
    const glm::dvec3 en(e);
    if (!(glm::dot(en, xIn) < e.w) || !(glm::dot(en, xOut) < e.w)) return false;
  }
  return true;
}

}  // namespace vistream
