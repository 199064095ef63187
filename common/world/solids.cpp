#include "common/world/solids.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <numeric>
#include <optional>
#include <unordered_map>

#include "common/core/check.h"

namespace vistream {
namespace {

// Upward directions for the parity test: one steep, eight alternating
// between 18 and 42 degrees of elevation. Azimuths are offset from the axes
// and elevations are not those of axis-aligned diagonals, so rays from the
// grid points free space tests from do not run along the edges of
// axis-aligned boxes.
std::array<glm::vec3, kSolidTestDirections> testDirections() {
  std::array<glm::vec3, kSolidTestDirections> d{};
  auto dir = [](double elevationDeg, double azimuthDeg) {
    const double e = elevationDeg * std::numbers::pi / 180.0;
    const double a = azimuthDeg * std::numbers::pi / 180.0;
    return glm::vec3(float(std::cos(e) * std::cos(a)), float(std::sin(e)),
                     float(std::cos(e) * std::sin(a)));
  };
  d[0] = dir(72.0, 7.0);
  for (int k = 0; k < kSolidTestDirections - 1; ++k)
    d[size_t(k) + 1] = dir(k % 2 ? 42.0 : 18.0, 23.0 + 45.0 * k);
  return d;
}

struct UnionFind {
  std::vector<uint32_t> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  uint32_t find(uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void unite(uint32_t a, uint32_t b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

// Distance along `dir` from `p` (inside `box`) to where the ray leaves the box.
float exitDistance(const Box3f& box, const glm::vec3& p, const glm::vec3& dir) {
  float t = std::numeric_limits<float>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (dir[a] > 0.0f) t = std::min(t, (box.hi[a] - p[a]) / dir[a]);
    if (dir[a] < 0.0f) t = std::min(t, (box.lo[a] - p[a]) / dir[a]);
  }
  return t;
}

// Topology the classification is made from: a vertex per welded corner and
// the edge pieces each triangle's sides are made of.
struct EdgeUse {
  uint64_t key;  // lower vertex << 32 | higher vertex
  uint32_t triangle;
  bool forward;  // walked from the lower vertex to the higher one
};

// Distinct positions of the corners of non-degenerate triangles: vertexOf
// (by corner 3 t + k) and each vertex's position.
void exactVertices(const FlatTriangles& tris, std::vector<uint32_t>& vertexOf,
                   std::vector<glm::dvec3>& position) {
  struct Corner {
    uint32_t key[3];
    uint32_t index;  // 3 * triangle + k
  };
  const size_t n = tris.size();
  std::vector<Corner> corners;
  corners.reserve(3 * n);
  for (size_t t = 0; t < n; ++t) {
    if (tris.degenerate[t]) continue;
    for (int k = 0; k < 3; ++k) {
      Corner c{};
      const glm::vec3 p = tris.vertex(t, k) + glm::vec3(0.0f);  // -0 and +0 weld
      std::memcpy(c.key, &p, sizeof(c.key));
      c.index = uint32_t(3 * t + size_t(k));
      corners.push_back(c);
    }
  }
  std::sort(corners.begin(), corners.end(), [](const Corner& a, const Corner& b) {
    return std::lexicographical_compare(a.key, a.key + 3, b.key, b.key + 3);
  });
  vertexOf.assign(3 * n, kNoHit);
  position.clear();
  for (size_t i = 0; i < corners.size(); ++i) {
    if (i == 0 || !std::equal(corners[i].key, corners[i].key + 3, corners[i - 1].key)) {
      glm::vec3 p;
      std::memcpy(&p, corners[i].key, sizeof(p));
      position.emplace_back(p);
    }
    vertexOf[corners[i].index] = uint32_t(position.size() - 1);
  }
}

// Welds vertices closer than `tol` (Euclidean): each vertex, in order, joins
// the nearest earlier representative within tol, or becomes one. No chains:
// every vertex lies within tol of its representative. Returns the
// representative of each vertex.
std::vector<uint32_t> weldVertices(const std::vector<glm::dvec3>& position, double tol) {
  struct KeyHash {
    size_t operator()(const glm::i64vec3& k) const {
      return size_t(k.x * 73856093LL) ^ size_t(k.y * 19349663LL) ^ size_t(k.z * 83492791LL);
    }
  };
  std::unordered_map<glm::i64vec3, std::vector<uint32_t>, KeyHash> cells;
  std::vector<uint32_t> rep(position.size());
  auto keyOf = [&](const glm::dvec3& p) { return glm::i64vec3(glm::floor(p / tol)); };
  for (uint32_t v = 0; v < position.size(); ++v) {
    const glm::i64vec3 k = keyOf(position[v]);
    uint32_t best = kNoHit;
    double bestD = tol;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = cells.find(k + glm::i64vec3(dx, dy, dz));
          if (it == cells.end()) continue;
          for (uint32_t r : it->second) {
            const double d = glm::distance(position[r], position[v]);
            if (d <= bestD) bestD = d, best = r;
          }
        }
    if (best == kNoHit) {
      cells[k].push_back(v);
      best = v;
    }
    rep[v] = best;
  }
  return rep;
}

// The edge uses of the triangles' sides over vertexOf. With tol > 0, a side
// that passes within tol of a vertex where the surface has a boundary (a
// vertex of a side used an odd number of times), away from its ends by more
// than tol, is cut there: a wall polygon whose corner lies on the long side
// of its neighbour (a T-junction) then shares the pieces.
std::vector<EdgeUse> edgeUses(const FlatTriangles& tris, const std::vector<uint8_t>& skip,
                              const std::vector<uint32_t>& vertexOf,
                              const std::vector<glm::dvec3>& position, double tol) {
  const size_t n = tris.size();
  std::vector<EdgeUse> uses;
  uses.reserve(3 * n);
  for (size_t t = 0; t < n; ++t) {
    if (skip[t]) continue;
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = vertexOf[3 * t + size_t(k)], b = vertexOf[3 * t + size_t((k + 1) % 3)];
      if (a == b) continue;
      uses.push_back({(uint64_t(std::min(a, b)) << 32) | std::max(a, b), uint32_t(t), a < b});
    }
  }
  auto byKey = [](const EdgeUse& x, const EdgeUse& y) {
    return x.key < y.key || (x.key == y.key && x.triangle < y.triangle);
  };
  std::sort(uses.begin(), uses.end(), byKey);
  if (tol <= 0.0) return uses;

  // Vertices on a boundary (an odd side), in an X/Z grid.
  std::vector<uint32_t> boundary;
  for (size_t i = 0; i < uses.size();) {
    size_t j = i;
    while (j < uses.size() && uses[j].key == uses[i].key) ++j;
    if ((j - i) % 2) {
      boundary.push_back(uint32_t(uses[i].key >> 32));
      boundary.push_back(uint32_t(uses[i].key));
    }
    i = j;
  }
  std::sort(boundary.begin(), boundary.end());
  boundary.erase(std::unique(boundary.begin(), boundary.end()), boundary.end());
  if (boundary.empty()) return uses;
  Box3f area;
  std::vector<Box3f> points(boundary.size());
  for (size_t i = 0; i < boundary.size(); ++i) {
    const glm::vec3 p(position[boundary[i]]);
    points[i] = Box3f{p, p};
    area.extend(p);
  }
  const float extent = std::max(area.hi.x - area.lo.x, area.hi.z - area.lo.z);
  const float cellSize = std::max({extent / 1024.0f, float(4.0 * tol), 0.25f});
  const XzGrid grid(area, cellSize, points);

  // Cut points of each distinct side: (parameter, vertex).
  std::vector<EdgeUse> out;
  out.reserve(uses.size());
  std::vector<std::pair<double, uint32_t>> cuts;
  const double step = 0.5 * cellSize;
  for (size_t i = 0; i < uses.size();) {
    size_t j = i;
    while (j < uses.size() && uses[j].key == uses[i].key) ++j;
    const uint32_t a = uint32_t(uses[i].key >> 32), b = uint32_t(uses[i].key);
    const glm::dvec3 pa = position[a], pb = position[b];
    const glm::dvec3 ab = pb - pa;
    const double len = glm::length(ab);
    cuts.clear();
    if (len > 2.0 * tol && area.overlaps(Box3f{glm::vec3(glm::min(pa, pb)) - float(tol),
                                               glm::vec3(glm::max(pa, pb)) + float(tol)})) {
      const int samples = int(std::ceil(len / step));
      // A vertex within tol of the side lies within tol + step / 2 of a sample.
      const float reach = float(tol + 0.5 * step);
      for (int s = 0; s <= samples; ++s) {
        const glm::dvec3 q = pa + ab * (double(s) / samples);
        const XzGrid::CellRange range = grid.cellsOverlapping(
            {float(q.x) - reach, float(q.z) - reach}, {float(q.x) + reach, float(q.z) + reach});
        for (int cz = range.lo.y; cz <= range.hi.y; ++cz)
          for (int cx = range.lo.x; cx <= range.hi.x; ++cx) {
            for (uint32_t item : grid.itemsIn({cx, cz})) {
              const uint32_t v = boundary[item];
              if (v == a || v == b) continue;
              const double along = glm::dot(position[v] - pa, ab) / len;
              if (along <= tol || along >= len - tol) continue;
              if (glm::distance(position[v], pa + ab * (along / len)) > tol) continue;
              cuts.emplace_back(along, v);
            }
          }
      }
    }
    if (cuts.empty()) {
      out.insert(out.end(), uses.begin() + ptrdiff_t(i), uses.begin() + ptrdiff_t(j));
    } else {
      std::sort(cuts.begin(), cuts.end());
      cuts.erase(std::unique(cuts.begin(), cuts.end(),
                             [](const auto& x, const auto& y) { return x.second == y.second; }),
                 cuts.end());
      for (size_t e = i; e < j; ++e) {
        uint32_t from = a;
        for (size_t k = 0; k <= cuts.size(); ++k) {
          const uint32_t to = k < cuts.size() ? cuts[k].second : b;
          if (to == from) continue;
          // Direction along the side: a -> b when the use walks it forward.
          const bool forward = uses[e].forward == (from < to);
          out.push_back({(uint64_t(std::min(from, to)) << 32) | std::max(from, to),
                         uses[e].triangle, forward});
          from = to;
        }
      }
    }
    i = j;
  }
  std::sort(out.begin(), out.end(), byKey);
  return out;
}

// The topology welded within `tol` (0: exact positions only): vertices,
// the triangles that collapse, and the edge pieces.
struct WeldedTopology {
  std::vector<uint32_t> vertexOf;    // by corner 3 t + k: welded vertex, kNoHit when skipped
  std::vector<glm::dvec3> position;  // by vertex (representatives carry their own position)
  std::vector<uint8_t> collapsed;    // by triangle: two corners weld
  std::vector<EdgeUse> edges;        // edge pieces, sorted by key
};

WeldedTopology weldTopology(const FlatTriangles& tris, double tol) {
  WeldedTopology w;
  const size_t n = tris.size();
  exactVertices(tris, w.vertexOf, w.position);
  // A triangle two of whose corners weld is thinner than the tolerance: it
  // takes no part in the topology and is a component of its own (open).
  w.collapsed.assign(n, 0);
  if (tol > 0.0) {
    const std::vector<uint32_t> rep = weldVertices(w.position, tol);
    for (uint32_t& v : w.vertexOf)
      if (v != kNoHit) v = rep[v];
    for (size_t t = 0; t < n; ++t) {
      if (tris.degenerate[t]) continue;
      uint32_t* v = &w.vertexOf[3 * t];
      if (v[0] == v[1] || v[1] == v[2] || v[2] == v[0]) {
        w.collapsed[t] = 1;
        v[0] = v[1] = v[2] = kNoHit;
      }
    }
  }
  std::vector<uint8_t> skip(n, 0);
  for (size_t t = 0; t < n; ++t) skip[t] = tris.degenerate[t] || w.collapsed[t];
  w.edges = edgeUses(tris, skip, w.vertexOf, w.position, tol);
  return w;
}

constexpr uint8_t kEnclosureNone = 0, kEnclosureSealed = 1, kEnclosureBaseOpen = 2;

// Peeling: a triangle with a side piece that no other remaining triangle
// uses, above its group's base (higher than the lowest point plus tol), is
// taken out, and so on until no such side is left. A dangling sheet (a party
// wall whose top meets the inside of a roof, not its edges) goes, the shell
// it hangs in stays; a surface with a real hole unravels whole. What remains
// of a group is an enclosure when each of its side pieces is used an even
// number of times (sealed) or the odd ones all lie at the base (base-open).
void findEnclosures(const std::vector<EdgeUse>& edges, const std::vector<glm::dvec3>& position,
                    double tol, const std::vector<uint32_t>& componentOf,
                    const std::vector<uint32_t>& groupOf, const std::vector<Box3f>& groupBounds,
                    std::vector<uint8_t>& groupEnclosure, std::vector<uint8_t>& peeled,
                    std::vector<float>& groupBaseTop) {
  const size_t n = componentOf.size();
  groupBaseTop.assign(groupBounds.size(), -std::numeric_limits<float>::infinity());
  peeled.assign(n, 0);
  groupEnclosure.assign(groupBounds.size(), kEnclosureSealed);
  // Runs of equal keys: one per side piece, with its remaining uses.
  std::vector<uint32_t> runStart, live;
  std::vector<uint8_t> atBase;
  std::vector<uint32_t> triStart(n + 1, 0), triRuns;
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++triStart[edges[j++].triangle + 1];
    const uint32_t g = groupOf[componentOf[edges[i].triangle]];
    const double top = double(groupBounds[g].lo.y) + tol;
    runStart.push_back(uint32_t(i));
    live.push_back(uint32_t(j - i));
    atBase.push_back(position[uint32_t(edges[i].key >> 32)].y <= top &&
                     position[uint32_t(edges[i].key)].y <= top);
    i = j;
  }
  runStart.push_back(uint32_t(edges.size()));
  for (size_t t = 0; t < n; ++t) triStart[t + 1] += triStart[t];
  triRuns.resize(triStart[n]);
  {
    std::vector<uint32_t> fill(triStart.begin(), triStart.end() - 1);
    for (uint32_t r = 0; r + 1 < runStart.size(); ++r)
      for (uint32_t e = runStart[r]; e < runStart[r + 1]; ++e)
        triRuns[fill[edges[e].triangle]++] = r;
  }
  std::vector<uint32_t> queue;
  for (uint32_t r = 0; r < live.size(); ++r)
    if (live[r] == 1 && !atBase[r]) queue.push_back(r);
  while (!queue.empty()) {
    const uint32_t r = queue.back();
    queue.pop_back();
    if (live[r] != 1) continue;
    uint32_t t = kNoHit;
    for (uint32_t e = runStart[r]; e < runStart[r + 1] && t == kNoHit; ++e)
      if (!peeled[edges[e].triangle]) t = edges[e].triangle;
    if (t == kNoHit) continue;
    peeled[t] = 1;
    for (uint32_t k = triStart[t]; k < triStart[t + 1]; ++k) {
      const uint32_t r2 = triRuns[k];
      if (live[r2] > 0 && --live[r2] == 1 && !atBase[r2]) queue.push_back(r2);
    }
  }
  // Side pieces left with an odd count decide each group.
  for (uint32_t r = 0; r < live.size(); ++r) {
    if (live[r] % 2 == 0) continue;
    const uint32_t g = groupOf[componentOf[edges[runStart[r]].triangle]];
    if (!atBase[r]) {
      groupEnclosure[g] = kEnclosureNone;
      continue;
    }
    if (groupEnclosure[g] == kEnclosureSealed) groupEnclosure[g] = kEnclosureBaseOpen;
    // The highest point of the open base: the cap stays below it.
    const float top = float(std::max(position[uint32_t(edges[runStart[r]].key >> 32)].y,
                                     position[uint32_t(edges[runStart[r]].key)].y));
    groupBaseTop[g] = std::max(groupBaseTop[g], top);
  }
  // A group peeled away entirely, or down to sheets at its base, encloses nothing.
  std::vector<uint8_t> rises(groupBounds.size(), 0);
  for (uint32_t r = 0; r < live.size(); ++r)
    if (live[r] > 0 && !atBase[r]) rises[groupOf[componentOf[edges[runStart[r]].triangle]]] = 1;
  for (size_t g = 0; g < groupBounds.size(); ++g)
    if (!rises[g]) groupEnclosure[g] = kEnclosureNone;
}

}  // namespace

const std::array<glm::vec3, kSolidTestDirections>& solidTestDirections() {
  static const std::array<glm::vec3, kSolidTestDirections> dirs = testDirections();
  return dirs;
}

const char* solidClassName(SolidClass c) {
  constexpr std::array<const char*, 5> kNames{"closed_outward", "closed_inward", "open",
                                              "non_manifold", "inconsistent"};  // by SolidClass
  return size_t(c) < kNames.size() ? kNames[size_t(c)] : "?";
}

Solids Solids::build(const FlatTriangles& tris, const SolidsOptions& options) {
  VS_CHECK(std::isfinite(options.weldTolerance) && options.weldTolerance >= 0.0);
  Solids s = classify(tris, 0.0);
  // Groups by X/Z cell of their bounds, for the inside tests (exact reading).
  Box3f all;
  for (const Box3f& b : s.groupBounds_) all.extend(b);
  if (!all.empty())
    s.grid_ = XzGrid(all, std::max({all.hi.x - all.lo.x, all.hi.z - all.lo.z, 1e-3f}) / 256.0f,
                     s.groupBounds_);
  // Sealed groups: the closed parity groups of the welded topology.
  std::optional<Solids> weldedReading;
  if (options.weldTolerance > 0.0) weldedReading = classify(tris, options.weldTolerance);
  const Solids& welded = weldedReading ? *weldedReading : s;
  s.weldedComponentOf_ = welded.componentOf_;
  s.weldedComponents_ = welded.components_;
  // Sealed groups, and enclosures: sealed groups and groups open only at
  // their base, without their peeled triangles. Both numbered in order of
  // first appearance.
  s.weldTolerance_ = options.weldTolerance;
  const size_t groups = welded.groupBounds_.size();
  std::vector<uint32_t> sealedOfGroup(groups, kNoHit), enclosureOfGroup(groups, kNoHit);
  auto number = [&](std::vector<uint32_t>& ofGroup, std::vector<Box3f>& bounds, uint32_t g) {
    if (ofGroup[g] == kNoHit) {
      ofGroup[g] = uint32_t(bounds.size());
      bounds.push_back(welded.groupBounds_[g]);
    }
    return ofGroup[g];
  };
  s.sealedOf_.assign(tris.size(), kNoHit);
  s.enclosureOf_.assign(tris.size(), kNoHit);
  for (size_t t = 0; t < tris.size(); ++t) {
    const uint32_t c = welded.componentOf(uint32_t(t));
    if (c == kNoHit) continue;
    const uint32_t g = welded.groupOf_[c];
    if (welded.groupSealed_[g]) s.sealedOf_[t] = number(sealedOfGroup, s.sealedBounds_, g);
    if (welded.groupEnclosure_[g] == kEnclosureNone || welded.peeled_[t]) continue;
    const size_t before = s.enclosureBounds_.size();
    s.enclosureOf_[t] = number(enclosureOfGroup, s.enclosureBounds_, g);
    if (s.enclosureBounds_.size() > before)
      s.enclosureFloor_.push_back(welded.groupEnclosure_[g] == kEnclosureSealed
                                      ? -std::numeric_limits<float>::infinity()
                                      : welded.groupBaseTop_[g]);
  }
  Box3f enclosed;
  for (const Box3f& b : s.enclosureBounds_) enclosed.extend(b);
  if (!enclosed.empty())
    s.enclosureGrid_ = XzGrid(
        enclosed,
        std::max({enclosed.hi.x - enclosed.lo.x, enclosed.hi.z - enclosed.lo.z, 1e-3f}) / 256.0f,
        s.enclosureBounds_);
  return s;
}

Solids Solids::classify(const FlatTriangles& tris, double tol) {
  Solids s;
  const size_t n = tris.size();
  s.componentOf_.assign(n, kNoHit);

  const WeldedTopology topo = weldTopology(tris, tol);
  const std::vector<uint8_t>& collapsed = topo.collapsed;
  const std::vector<glm::dvec3>& position = topo.position;
  const std::vector<EdgeUse>& edges = topo.edges;

  // Components: triangles joined across manifold edges (used by exactly two
  // triangles). A vertex or a non-manifold edge does not join, so a floor
  // sheet stays apart from the wall boxes standing on it and two boxes
  // sharing an edge stay two.
  UnionFind uf(n);
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    if (j - i == 2) uf.unite(edges[i].triangle, edges[i + 1].triangle);
    i = j;
  }
  std::vector<uint32_t> componentOfRoot(n, kNoHit);
  for (size_t t = 0; t < n; ++t) {
    if (tris.degenerate[t]) continue;
    const uint32_t root = uf.find(uint32_t(t));
    if (componentOfRoot[root] == kNoHit) {
      componentOfRoot[root] = uint32_t(s.components_.size());
      s.components_.emplace_back();
    }
    const uint32_t c = componentOfRoot[root];
    s.componentOf_[t] = c;
    SolidComponent& comp = s.components_[c];
    ++comp.triangles;
    for (int k = 0; k < 3; ++k) comp.bounds.extend(tris.vertex(t, k));
  }
  const size_t nc = s.components_.size();
  // oddEdge: some edge piece is used an odd number of times (the component
  // bounds no volume by itself, or with the others of its group).
  std::vector<uint8_t> open(nc, 0), nonManifold(nc, 0), inconsistent(nc, 0), oddEdge(nc, 0);
  for (size_t t = 0; t < n; ++t)
    if (collapsed[t]) open[s.componentOf_[t]] = oddEdge[s.componentOf_[t]] = 1;
  for (size_t i = 0; i < edges.size();) {
    size_t j = i, forward = 0;
    while (j < edges.size() && edges[j].key == edges[i].key) forward += edges[j++].forward;
    const size_t uses = j - i;
    for (size_t e = i; e < j; ++e) {
      const uint32_t c = s.componentOf_[edges[e].triangle];
      if (uses == 1) open[c] = 1;
      if (uses > 2) nonManifold[c] = 1;
      if (uses == 2 && forward != 1) inconsistent[c] = 1;
      if (uses % 2) oddEdge[c] = 1;
    }
    i = j;
  }

  // Signed volume about each component's centre (precision far from the origin).
  std::vector<double> volume(s.components_.size(), 0.0);
  for (size_t t = 0; t < n; ++t) {
    if (tris.degenerate[t]) continue;
    const uint32_t c = s.componentOf_[t];
    const glm::dvec3 o(s.components_[c].bounds.center());
    const glm::dvec3 a = glm::dvec3(tris.vertex(t, 0)) - o, b = glm::dvec3(tris.vertex(t, 1)) - o,
                     d = glm::dvec3(tris.vertex(t, 2)) - o;
    volume[c] += glm::dot(a, glm::cross(b, d)) / 6.0;
  }

  // Distinct faces per component.
  std::vector<uint64_t> faceKeys;
  faceKeys.reserve(n);
  for (size_t t = 0; t < n; ++t)
    if (!tris.degenerate[t])
      faceKeys.push_back((uint64_t(s.componentOf_[t]) << 32) | tris.faceIds[t]);
  std::sort(faceKeys.begin(), faceKeys.end());
  faceKeys.erase(std::unique(faceKeys.begin(), faceKeys.end()), faceKeys.end());
  for (uint64_t k : faceKeys) ++s.components_[size_t(k >> 32)].faces;

  for (size_t c = 0; c < s.components_.size(); ++c) {
    SolidComponent& comp = s.components_[c];
    comp.signedVolume = volume[c];
    if (nonManifold[c])
      comp.kind = SolidClass::NonManifold;
    else if (open[c])
      comp.kind = SolidClass::Open;
    else if (inconsistent[c])
      comp.kind = SolidClass::Inconsistent;
    else
      comp.kind = volume[c] > 0.0 ? SolidClass::ClosedOutward : SolidClass::ClosedInward;
  }

  // Parity groups: components joined at non-manifold edges. Two cubes
  // sharing a face split into pieces at the shared square's edges; counted
  // together, a ray leaving one cube through the shared face (two coincident
  // faces) and then the other still crosses an odd number of times.
  UnionFind groups(s.components_.size());
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    if (j - i > 2)
      for (size_t e = i + 1; e < j; ++e)
        groups.unite(s.componentOf_[edges[i].triangle], s.componentOf_[edges[e].triangle]);
    i = j;
  }
  s.groupOf_.assign(s.components_.size(), kNoHit);
  for (size_t c = 0; c < s.components_.size(); ++c) {
    const uint32_t root = groups.find(uint32_t(c));
    if (s.groupOf_[root] == kNoHit) {
      s.groupOf_[root] = uint32_t(s.groupBounds_.size());
      s.groupBounds_.emplace_back();
    }
    s.groupOf_[c] = s.groupOf_[root];
    s.groupBounds_[s.groupOf_[c]].extend(s.components_[c].bounds);
  }
  s.groupClosed_.assign(s.groupBounds_.size(), 1);
  s.groupSealed_.assign(s.groupBounds_.size(), 1);
  for (size_t c = 0; c < s.components_.size(); ++c) {
    const SolidClass k = s.components_[c].kind;
    if (k != SolidClass::ClosedOutward && k != SolidClass::ClosedInward)
      s.groupClosed_[s.groupOf_[c]] = 0;
    if (oddEdge[c]) s.groupSealed_[s.groupOf_[c]] = 0;
  }
  // Enclosures: peel dangling sheets, then keep the groups whose remaining
  // odd edge pieces (if any) all lie at their base.
  findEnclosures(edges, position, tol, s.componentOf_, s.groupOf_, s.groupBounds_,
                 s.groupEnclosure_, s.peeled_, s.groupBaseTop_);
  return s;
}

FlatTriangles weldedSurface(const FlatTriangles& tris, double tol,
                            std::vector<uint32_t>& originalOf) {
  VS_CHECK(std::isfinite(tol) && tol >= 0.0);
  const WeldedTopology topo = weldTopology(tris, tol);
  // Each triangle's directed side pieces, in edge order.
  std::vector<std::array<uint32_t, 3>> pieces;  // triangle, from, to
  pieces.reserve(topo.edges.size());
  for (const EdgeUse& e : topo.edges) {
    const uint32_t lo = uint32_t(e.key >> 32), hi = uint32_t(e.key);
    pieces.push_back(e.forward ? std::array{e.triangle, lo, hi} : std::array{e.triangle, hi, lo});
  }
  std::sort(pieces.begin(), pieces.end());
  FlatTriangles out;
  originalOf.clear();
  auto emit = [&](uint32_t t, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
    const glm::vec3 fa(a), fb(b), fc(c);
    out.positions.insert(out.positions.end(), {fa, fb, fc});
    out.faceIds.push_back(tris.faceIds[t]);
    out.objectIds.push_back(tris.objectIds[t]);
    out.degenerate.push_back(isDegenerateTriangle(fa, fb, fc) ? 1 : 0);
    originalOf.push_back(t);
  };
  std::vector<uint32_t> loop;
  for (size_t i = 0; i < pieces.size();) {
    const uint32_t t = pieces[i][0];
    size_t j = i;
    while (j < pieces.size() && pieces[j][0] == t) ++j;
    // Walk the boundary from the first corner; a side without pieces (its
    // corners welded away) or a broken walk keeps the welded corners.
    loop.assign(1, topo.vertexOf[3 * size_t(t)]);
    while (loop.size() <= j - i) {
      uint32_t next = kNoHit;
      for (size_t k = i; k < j && next == kNoHit; ++k)
        if (pieces[k][1] == loop.back()) next = pieces[k][2];
      if (next == kNoHit || next == loop.front()) break;
      loop.push_back(next);
    }
    const auto& P = topo.position;
    if (loop.size() <= 3) {
      emit(t, P[topo.vertexOf[3 * size_t(t)]], P[topo.vertexOf[3 * size_t(t) + 1]],
           P[topo.vertexOf[3 * size_t(t) + 2]]);
    } else {
      // Cut at T-junctions: a fan from the centroid of the boundary points,
      // which lies inside the triangle, so no piece is degenerate.
      glm::dvec3 centre(0.0);
      for (uint32_t v : loop) centre += P[v];
      centre /= double(loop.size());
      for (size_t k = 0; k < loop.size(); ++k)
        emit(t, centre, P[loop[k]], P[loop[(k + 1) % loop.size()]]);
    }
    i = j;
  }
  return out;
}

size_t Solids::sealedTriangles() const {
  return size_t(
      std::count_if(sealedOf_.begin(), sealedOf_.end(), [](uint32_t g) { return g != kNoHit; }));
}

SolidCensus Solids::census() const {
  SolidCensus out;
  for (const SolidComponent& c : components_) {
    const size_t k = size_t(c.kind);
    ++out.components[k];
    out.triangles[k] += c.triangles;
    out.faces[k] += c.faces;
  }
  return out;
}

bool Solids::inside(const RayQuery& rays, const glm::vec3& p) const {
  return insideGroup(rays, p, false, false);
}

bool Solids::insideClosed(const RayQuery& rays, const glm::vec3& p) const {
  return insideGroup(rays, p, true, true);
}

// inside() || insideClosed() in one pass: inside a closed group is inside a
// group, so the vote over every group decides both, and an eye on a closed
// group's surface is unserved whatever the vote; then insideEnclosure().
bool Solids::unservedViewpoint(const RayQuery& rays, const glm::vec3& p) const {
  return insideGroup(rays, p, false, true) || insideEnclosure(rays, p);
}

namespace {

// Parity along one ray, the core of every inside test: into `odd`, sorted
// and each once, the ids (idOf(triangle); kNoHit counts for nothing) whose
// triangles `ray` crosses an odd number of times. Returns the triangle of a
// hit at the ray's start (the ray starts on a surface), with `odd` empty,
// or kNoHit.
template <class IdOf>
uint32_t oddIds(const RayQuery& rays, const Ray& ray, IdOf&& idOf, std::vector<uint32_t>& odd) {
  thread_local std::vector<Hit> hits;
  hits.clear();
  odd.clear();
  rays.allHits(ray, hits);
  for (const Hit& h : hits) {
    if (h.t <= 0.0f) {
      odd.clear();
      return h.triangle;
    }
    if (const uint32_t id = idOf(h.triangle); id != kNoHit) odd.push_back(id);
  }
  std::sort(odd.begin(), odd.end());
  size_t w = 0;
  for (size_t i = 0; i < odd.size();) {
    size_t j = i;
    while (j < odd.size() && odd[j] == odd[i]) ++j;
    if ((j - i) % 2) odd[w++] = odd[i];
    i = j;
  }
  odd.resize(w);
  return kNoHit;
}

// Strict-majority parity vote along the upward test directions: true when
// some candidate has odd parity along more than half of them. `idOf(t)`
// names the candidate triangle t belongs to (or kNoHit), `boundsOf(c)` a
// candidate's box; a hit at the ray's start (the point lies on a surface)
// returns onSurface(t) at once.
template <class IdOf, class BoundsOf, class OnSurface>
bool oddMajority(const RayQuery& rays, const glm::vec3& p, std::span<const uint32_t> candidates,
                 IdOf&& idOf, BoundsOf&& boundsOf, OnSurface&& onSurface) {
  thread_local std::vector<int> votes;
  thread_local std::vector<uint32_t> odd;
  votes.assign(candidates.size(), 0);
  const std::array<glm::vec3, kSolidTestDirections>& dirs = solidTestDirections();
  for (int d = 0; d < kSolidTestDirections; ++d) {
    const glm::vec3& dir = dirs[size_t(d)];
    float tfar = 0.0f;
    for (uint32_t c : candidates) tfar = std::max(tfar, exitDistance(boundsOf(c), p, dir));
    if (const uint32_t t = oddIds(rays, Ray{p, dir, 0.0f, tfar * 1.001f + 1e-3f}, idOf, odd);
        t != kNoHit)
      return onSurface(t);
    // Decide as soon as the vote is settled for every candidate.
    const int remaining = kSolidTestDirections - d - 1;
    bool undecided = false;
    for (size_t i = 0; i < candidates.size(); ++i) {
      votes[i] += std::binary_search(odd.begin(), odd.end(), candidates[i]) ? 1 : 0;
      if (2 * votes[i] > kSolidTestDirections) return true;
      if (2 * (votes[i] + remaining) > kSolidTestDirections) undecided = true;
    }
    if (!undecided) return false;
  }
  return false;
}

}  // namespace

bool Solids::insideGroup(const RayQuery& rays, const glm::vec3& p, bool closedOnly,
                         bool closedSurfaceInside) const {
  if (grid_.empty()) return false;
  thread_local std::vector<uint32_t> candidates;
  candidates.clear();
  for (uint32_t g : grid_.itemsIn(grid_.cellOf({p.x, p.z})))
    if (groupBounds_[g].contains(p) && (!closedOnly || groupClosed_[g])) candidates.push_back(g);
  if (candidates.empty()) return false;
  // The group of a hit triangle; kNoHit for one these solids were not built from.
  auto groupOfHit = [&](uint32_t t) {
    const uint32_t c = t < componentOf_.size() ? componentOf_[t] : kNoHit;
    return c == kNoHit ? kNoHit : groupOf_[c];
  };
  return oddMajority(
      rays, p, candidates, groupOfHit, [&](uint32_t g) -> const Box3f& { return groupBounds_[g]; },
      // On a surface: outside by convention, except on the surface of a
      // closed solid for insideClosed (whose contract counts the surface in).
      [&](uint32_t t) {
        const uint32_t g = groupOfHit(t);
        return closedSurfaceInside && g != kNoHit && groupClosed_[g];
      });
}

bool Solids::insideEnclosure(const RayQuery& rays, const glm::vec3& p) const {
  if (enclosureGrid_.empty()) return false;
  thread_local std::vector<uint32_t> candidates;
  candidates.clear();
  for (uint32_t e : enclosureGrid_.itemsIn(enclosureGrid_.cellOf({p.x, p.z})))
    if (enclosureBounds_[e].contains(p) && p.y > enclosureFloor_[e]) candidates.push_back(e);
  if (candidates.empty()) return false;
  return oddMajority(
      rays, p, candidates, [&](uint32_t t) { return enclosureOfHit(t); },
      [&](uint32_t e) -> const Box3f& { return enclosureBounds_[e]; },
      [&](uint32_t t) { return enclosureOfHit(t) != kNoHit; });
}

bool Solids::oddEnclosures(const RayQuery& rays, const Ray& ray, std::vector<uint32_t>& odd) const {
  return oddIds(
             rays, ray, [&](uint32_t t) { return enclosureOfHit(t); }, odd) == kNoHit;
}

int Solids::enclosureVotes(const RayQuery& rays, const glm::vec3& p, uint32_t enclosure) const {
  const Box3f& box = enclosureBounds_[enclosure];
  const float reach = glm::length(box.hi - box.lo) + glm::length(p - box.center()) + 1.0f;
  thread_local std::vector<uint32_t> odd;
  int votes = 0;
  for (const glm::vec3& dir : solidTestDirections()) {
    if (!oddEnclosures(rays, Ray{p, dir, 0.0f, reach}, odd)) return -1;
    votes += std::binary_search(odd.begin(), odd.end(), enclosure) ? 1 : 0;
  }
  return votes;
}

}  // namespace vistream
