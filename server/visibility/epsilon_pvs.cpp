// Cohen-Or and Zadicario 1998, "Visibility Streaming for Network-based
// Walkthroughs": the conservative epsilon-visibility test (section 3), ray
// shooting through a space subdivision with an incremental candidate set
// (section 4) and the optimisations of Table 2.
//
// Why the reduced set of lines is enough (the "redundant rays" of the paper,
// made exact). Let C be the cell, V the occludee's vertices, O the open
// convex occluder region. Suppose every kept line (c, v) crosses O but some
// segment [x, y], x in C, y in hull(V), misses it. Then a plane separates the
// segment from O: a closed half-space {n.p <= k} holds the segment and not
// one point of O. Let c* minimise n.p over C and v* over V (perturbing n to
// break ties keeps them minimisers of the original n). n.c* <= n.x <= k and
// n.v* <= n.y <= k, so all of [c*, v*] lies in the half-space and misses O.
// But (c*, v*) is a kept line by construction (c*'s normal cone, an octant,
// meets v*'s normal cone in n), a contradiction. So blocking every kept line
// blocks every line from the cell to the occludee.
#include "server/visibility/epsilon_pvs.h"

#include <algorithm>
#include <array>
#include <map>
#include <numeric>
#include <set>
#include <span>

#include "common/core/check.h"
#include "common/core/timer.h"
#include "common/raycast/ray_query.h"
#include "common/world/back_faces.h"
#include "common/world/solids.h"
#include "server/visibility/horizon_fusion.h"
#include "server/visibility/planar_fusion.h"

namespace vistream {

struct EpsilonPvs::Face {
  uint32_t id = 0;
  std::vector<glm::dvec3> vertices;
  std::vector<std::pair<uint8_t, uint8_t>> keptLines;  // (cell corner pattern, vertex index)
  // One-sided faces only (every non-degenerate triangle in a closed,
  // consistently outward solid): the planes of its triangles, wound as in
  // the scene. Empty: the face is two-sided.
  struct FrontPlane {
    glm::dvec3 n{0.0};       // unit normal, to the front
    double offset = 0.0;     // n . a for a corner a
    double magnitude = 0.0;  // |a|, for the rounding margin
  };
  std::vector<FrontPlane> oneSided;
  uint32_t solid = kNoHit;  // one-sided faces: their solid (EpsilonPvs::solidFloor_)
  bool hasArea = false;     // some triangle is not degenerate
};

// A spatially compact group of one object's faces with its bounding box:
// the occludee of the bounding-box stage. Small objects are one group; large
// ones (a ground made of 2,000 tiles) are split so that the box stage can
// cull their far parts.
struct OccludeeGroup {
  std::array<glm::dvec3, 8> boxCorners{};
  Box3f bounds;
  uint32_t firstFace = 0, faceCount = 0;  // range in ObjectEntry::faces
};

struct EpsilonPvs::ObjectEntry {
  uint32_t object = 0;
  bool dynamic = false;
  Box3f bounds;
  std::vector<Face> faces;
  std::vector<OccludeeGroup> groups;
};

namespace {

// Cell corner for pattern s: bit i set takes the upper bound on axis i.
glm::dvec3 cellCorner(const Box3f& cell, int s) {
  return {(s & 1) ? cell.hi.x : cell.lo.x, (s & 2) ? cell.hi.y : cell.lo.y,
          (s & 4) ? cell.hi.z : cell.lo.z};
}

// Is there a nonzero n with a.n >= 0 for every a in `constraints`? Decided by
// the extreme rays of the cone (pairwise cross products), with a tolerance
// that errs towards "yes" (keeping a line is always safe).
bool coneNonEmpty(const std::vector<glm::dvec3>& constraints) {
  auto feasible = [&](const glm::dvec3& r) {
    const double rl = glm::length(r);
    if (!(rl > 0.0)) return false;
    for (const glm::dvec3& a : constraints)
      if (glm::dot(a, r) < -1e-9 * glm::length(a) * rl) return false;
    return true;
  };
  for (size_t i = 0; i < constraints.size(); ++i)
    for (size_t j = i + 1; j < constraints.size(); ++j) {
      const glm::dvec3 r = glm::cross(constraints[i], constraints[j]);
      if (feasible(r) || feasible(-r)) return true;
    }
  return false;
}

// The lines (cell corner pattern, vertex) that can lie on the convex hull of
// an axis-aligned cell and the vertex set; see the proof at the top.
std::vector<std::pair<uint8_t, uint8_t>> keptLinesFor(const std::vector<glm::dvec3>& verts) {
  std::vector<std::pair<uint8_t, uint8_t>> out;
  std::vector<glm::dvec3> constraints;
  for (size_t k = 0; k < verts.size(); ++k) {
    for (int s = 0; s < 8; ++s) {
      constraints.clear();
      // The corner with pattern s minimises n.p over the cell iff n_i <= 0
      // on axes where it takes the upper bound and n_i >= 0 elsewhere.
      for (int i = 0; i < 3; ++i) {
        glm::dvec3 a(0.0);
        a[i] = (s >> i & 1) ? -1.0 : 1.0;
        constraints.push_back(a);
      }
      // v_k minimises n.p over the occludee iff n.(w - v_k) >= 0 for all w.
      for (size_t w = 0; w < verts.size(); ++w)
        if (w != k && verts[w] != verts[k]) constraints.push_back(verts[w] - verts[k]);
      if (coneNonEmpty(constraints)) out.emplace_back(uint8_t(s), uint8_t(k));
    }
  }
  return out;
}

// At most this many faces per box-stage group: tuned on city1, where the
// ground's 2,128 tiles dominate the face stage when tested one by one.
constexpr size_t kMaxFacesPerGroup = 32;

// Splits faces [first, first+count) at the median centroid of the longest
// axis until groups are small, reordering `faces` in place.
void splitGroups(std::vector<EpsilonPvs::Face>& faces, uint32_t first, uint32_t count,
                 std::vector<OccludeeGroup>& out);

}  // namespace

namespace {

// Which faces may be culled for facing away: those whose every
// non-degenerate triangle has the inside of one solid behind it, by the
// orientation or the parity proof of common/world/back_faces.h. Per face the
// solid's index into `bounds`/`floor`, or kNoHit for a two-sided face.
struct OneSidedFaces {
  std::vector<uint32_t> solidOf;           // by face ID
  std::vector<float> floor;                // by solid: a viewpoint must lie above this y
  size_t byOrientation = 0, byParity = 0;  // triangles
};

// Over the static world's triangles, solids and rays when given (parts
// Solids or more), else over its own.
OneSidedFaces oneSidedFaces(const Scene& scene, const StaticWorld* world) {
  StaticWorld own;  // without the ground decision, which back faces do not need
  if (!world) {
    own.triangles = std::make_unique<const FlatTriangles>(flattenScene(scene, /*staticOnly=*/true));
    own.rays = makeEmbreeRayQuery(*own.triangles);
    own.solids = Solids::build(*own.triangles);
    world = &own;
  }
  VS_CHECK(world->triangles && world->rays);
  // The solids part was built (a scene with triangles has components).
  VS_CHECK(world->triangles->size() == 0 || !world->solids.components().empty());
  const FlatTriangles& flat = *world->triangles;
  BackFaceSolids behind = backFaceSolids(flat, world->solids, *world->rays);
  constexpr uint32_t kUnseen = kNoHit - 1;
  OneSidedFaces out;
  out.solidOf.assign(scene.faceCount, kUnseen);
  for (size_t t = 0; t < flat.size(); ++t) {
    const uint32_t face = flat.faceIds[t];
    if (face >= out.solidOf.size() || flat.degenerate[t]) continue;
    const uint32_t c = behind.solidOf[t];
    uint32_t& s = out.solidOf[face];
    s = c != kNoHit && (s == kUnseen || s == c) ? c : kNoHit;
  }
  for (uint32_t& s : out.solidOf)
    if (s == kUnseen) s = kNoHit;
  out.floor = std::move(behind.floor);
  out.byOrientation = behind.byOrientation;
  out.byParity = behind.byParity;
  return out;
}

}  // namespace

EpsilonPvs::EpsilonPvs(const Scene& scene, const OccluderOptions& occluderOptions,
                       const StaticWorld* world)
    : scene_(scene) {
  Stopwatch clock;
  occluders_ = extractOccluders(scene, occluderOptions);
  planar_ = std::make_unique<PlanarFusion>(occluders_);
  OneSidedFaces oneSided = oneSidedFaces(scene, world);
  solidFloor_ = std::move(oneSided.floor);
  std::vector<Box3f> bounds;
  bounds.reserve(occluders_.occluders.size());
  for (const auto& o : occluders_.occluders) bounds.push_back(o.bounds);
  occluderTree_ = KdTree::build(bounds);

  objects_.reserve(scene.objects.size());
  for (uint32_t oi = 0; oi < scene.objects.size(); ++oi) {
    const Object& o = scene.objects[oi];
    ObjectEntry e;
    e.object = oi;
    e.dynamic = o.dynamic;
    e.bounds = o.bounds;
    std::map<uint32_t, Face> byFace;
    std::set<uint32_t> twoSided;
    for (size_t t = 0; t < o.mesh.triangles.size(); ++t) {
      Face& f = byFace[o.mesh.faceIds[t]];
      std::array<size_t, 3> corner{};
      for (int k = 0; k < 3; ++k) {
        const glm::dvec3 v(o.mesh.positions[o.mesh.triangles[t][k]]);
        const auto it = std::find(f.vertices.begin(), f.vertices.end(), v);
        corner[size_t(k)] = size_t(it - f.vertices.begin());
        if (it == f.vertices.end()) f.vertices.push_back(v);
      }
      // Degenerate triangles are never hit: they need not face away.
      const bool distinct = corner[0] != corner[1] && corner[1] != corner[2] &&
                            corner[0] != corner[2] &&
                            !isDegenerateTriangle(o.mesh.positions[o.mesh.triangles[t][0]],
                                                  o.mesh.positions[o.mesh.triangles[t][1]],
                                                  o.mesh.positions[o.mesh.triangles[t][2]]);
      f.hasArea |= distinct;
      if (distinct && corner[0] < 255 && corner[1] < 255 && corner[2] < 255) {
        const glm::dvec3& a = f.vertices[corner[0]];
        const glm::dvec3 n = glm::cross(f.vertices[corner[1]] - a, f.vertices[corner[2]] - a);
        const double len = glm::length(n);
        // A zero normal cannot face away: the face stays two-sided.
        if (!(len > 0.0))
          twoSided.insert(o.mesh.faceIds[t]);
        else
          f.oneSided.push_back({n / len, glm::dot(n / len, a), glm::length(a)});
      }
    }
    for (auto& [id, f] : byFace) {
      f.id = id;
      VS_CHECK_LE(f.vertices.size(), 255u * 3u);
      if (f.vertices.size() <= 255) f.keptLines = keptLinesFor(f.vertices);
      f.solid = id < oneSided.solidOf.size() ? oneSided.solidOf[id] : kNoHit;
      if (f.vertices.size() > 255 || f.solid == kNoHit || twoSided.count(id)) {
        f.oneSided.clear();
        f.solid = kNoHit;
      }
      f.oneSided.shrink_to_fit();
      e.faces.push_back(std::move(f));
    }
    splitGroups(e.faces, 0, uint32_t(e.faces.size()), e.groups);
    objects_.push_back(std::move(e));
  }
  faceIndex_.assign(scene.faceCount, {~0u, ~0u});
  for (uint32_t e = 0; e < objects_.size(); ++e)
    for (uint32_t f = 0; f < objects_[e].faces.size(); ++f)
      if (objects_[e].faces[f].id < faceIndex_.size()) faceIndex_[objects_[e].faces[f].id] = {e, f};
  occludersOf_.resize(scene.objects.size());
  for (uint32_t i = 0; i < occluders_.occluders.size(); ++i)
    occludersOf_[occluders_.occluders[i].object].push_back(i);
  prepareMs_ = clock.ms();
}

const std::vector<glm::dvec3>* EpsilonPvs::faceVertices(uint32_t faceId) const {
  if (faceId >= faceIndex_.size() || faceIndex_[faceId].first == ~0u) return nullptr;
  return &objects_[faceIndex_[faceId].first].faces[faceIndex_[faceId].second].vertices;
}

EpsilonPvs::~EpsilonPvs() = default;

namespace {

Box3f faceBounds(const EpsilonPvs::Face& f) {
  Box3f b;
  for (const glm::dvec3& v : f.vertices) b.extend(glm::vec3(v));
  return b;
}

void splitGroups(std::vector<EpsilonPvs::Face>& faces, uint32_t first, uint32_t count,
                 std::vector<OccludeeGroup>& out) {
  Box3f bounds;
  for (uint32_t i = first; i < first + count; ++i) bounds.extend(faceBounds(faces[i]));
  if (count <= kMaxFacesPerGroup) {
    OccludeeGroup g;
    g.bounds = bounds;
    for (int s = 0; s < 8; ++s) g.boxCorners[size_t(s)] = cellCorner(bounds, s);
    g.firstFace = first;
    g.faceCount = count;
    if (count > 0) out.push_back(g);
    return;
  }
  const int axis = bounds.longestAxis();
  const auto begin = faces.begin() + first, end = begin + count, mid = begin + count / 2;
  std::nth_element(begin, mid, end, [axis](const EpsilonPvs::Face& a, const EpsilonPvs::Face& b) {
    return faceBounds(a).center()[axis] < faceBounds(b).center()[axis];
  });
  splitGroups(faces, first, count / 2, out);
  splitGroups(faces, first + count / 2, count - count / 2, out);
}

// The cell as facesAway reads it, computed once per cell.
struct CellSupport {
  glm::dvec3 centre{0.0}, half{0.0};
  double margin = 0.0;  // occluderMargin of the cell's coordinates
  explicit CellSupport(const Box3f& cell)
      : centre(cell.center()),
        half(0.5 * (glm::dvec3(cell.hi) - glm::dvec3(cell.lo))),
        margin(occluderMargin(
            std::max(glm::length(glm::dvec3(cell.hi)), glm::length(glm::dvec3(cell.lo))))) {}
};

// True if the closed cell lies strictly behind the plane of every triangle
// of a one-sided face, by more than the rounding margin, and above the
// face's solid's floor (`floor`: the cap of a solid open at its base): no
// point of the cell sees the face's front, and none lies where a line could
// pass below the solid's open base. Viewpoints of the cell inside the solid
// or on its surface (which would look into it past the surface they stand
// on) are not served (Solids::unservedViewpoint).
// In double from float inputs: the unit normals and offsets (made once,
// with the face) and the box support are exact to a few ulps, far below
// the margin.
bool facesAway(const EpsilonPvs::Face& f, const Box3f& cell, const CellSupport& c, float floor) {
  if (f.oneSided.empty() || !(cell.lo.y > floor)) return false;
  for (const EpsilonPvs::Face::FrontPlane& p : f.oneSided) {
    // The largest signed distance of a cell point from the plane.
    const double support = glm::dot(p.n, c.centre) - p.offset + glm::dot(glm::abs(p.n), c.half);
    if (!(support < -std::max(c.margin, occluderMargin(p.magnitude)))) return false;
  }
  return true;
}

}  // namespace

// One cell's computation: scratch state and the occlusion test.
struct PvsQuery {
  const EpsilonPvs& pvs;
  const PvsOptions& options;
  Box3f cell;
  std::array<glm::dvec3, 8> corners{};
  std::vector<uint32_t> stamp;  // per occluder: last line that tested it
  uint32_t lineId = 0;
  std::vector<uint8_t> allowed;  // per occluder
  std::vector<uint8_t> used;     // per occluder: culled something
  std::vector<uint32_t> candidates, survivors, found;
  static constexpr uint32_t kNone = 0xffffffffu;
  std::array<uint32_t, 4> recent{kNone, kNone, kNone, kNone};  // most recently successful occluders
  PvsStats& stats;

  void markUsed(uint32_t c) {
    used[c] = 1;
    if (recent[0] == c) return;
    const auto it = std::find(recent.begin(), recent.end(), c);
    std::rotate(recent.begin(), it == recent.end() ? recent.end() - 1 : it,
                it == recent.end() ? recent.end() : it + 1);
    recent[0] = c;
  }

  PvsQuery(const EpsilonPvs& p, const PvsOptions& o, const Box3f& c, PvsStats& s)
      : pvs(p), options(o), cell(c), stats(s) {
    for (int i = 0; i < 8; ++i) corners[size_t(i)] = cellCorner(cell, i);
    const size_t n = pvs.occluders_.occluders.size();
    stamp.assign(n, 0);
    allowed.assign(n, 1);
    used.assign(n, 0);
    if (options.largeOccluders > 0 && options.largeOccluders < n) {
      // Solid angle of each occluder from the cell centre, area / distance^2.
      const glm::dvec3 centre(cell.center());
      std::vector<std::pair<double, uint32_t>> score(n);
      for (uint32_t i = 0; i < n; ++i) {
        const auto& oc = pvs.occluders_.occluders[i];
        const glm::dvec3 d = oc.centre - centre;
        score[i] = {oc.area / (glm::dot(d, d) + 1e-6), i};
      }
      std::nth_element(score.begin(), score.begin() + std::ptrdiff_t(options.largeOccluders),
                       score.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
      allowed.assign(n, 0);
      for (size_t i = 0; i < options.largeOccluders; ++i) allowed[score[i].second] = 1;
    }
    stats.occluders = options.largeOccluders > 0 ? std::min(options.largeOccluders, n) : n;
  }

  // Calls f(i) for every allowed occluder i blocking the segment a-b, front
  // to back through the kD-tree, each once; f returns false to stop.
  template <typename F>
  void forEachBlocker(const glm::dvec3& a, const glm::dvec3& b, uint64_t& tests, F&& f) {
    ++lineId;
    const auto& occ = pvs.occluders_.occluders;
    pvs.occluderTree_.traverseRay(glm::vec3(a), glm::vec3(b - a), 0.0f, 1.0f,
                                  [&](int32_t leaf, float, float) {
                                    for (uint32_t i : pvs.occluderTree_.items(leaf)) {
                                      if (!allowed[i] || stamp[i] == lineId) continue;
                                      stamp[i] = lineId;
                                      ++tests;
                                      if (occluderBlocksSegment(occ[i], a, b) && !f(i))
                                        return false;
                                    }
                                    return true;
                                  });
  }

  // Every allowed occluder blocking the segment a-b.
  void collect(const glm::dvec3& a, const glm::dvec3& b, uint64_t& tests,
               std::vector<uint32_t>& out) {
    out.clear();
    ++stats.linesCast;
    forEachBlocker(a, b, tests, [&](uint32_t i) {
      out.push_back(i);
      return true;
    });
  }

  // True if one occluder blocks every listed line. `firstOnly` reports
  // whether the first candidate was the one.
  bool hidden(std::span<const glm::dvec3> points,
              std::span<const std::pair<uint8_t, uint8_t>> lines, uint64_t& tests, bool* byFirst) {
    if (lines.empty()) return false;
    const auto& occ = pvs.occluders_.occluders;
    auto lineEnds = [&](const std::pair<uint8_t, uint8_t>& l) {
      return std::pair{corners[l.first], points[l.second]};
    };
    if (options.incremental) {
      // Occluders that just culled a neighbour are tried first: adjacent
      // faces and groups are usually hidden by the same building.
      bool first = true;
      auto blocksAll = [&](uint32_t c, size_t from) {
        for (size_t l = from; l < lines.size(); ++l) {
          const auto [a, b] = lineEnds(lines[l]);
          ++tests;
          if (!occluderBlocksSegment(occ[c], a, b)) return false;
        }
        return true;
      };
      for (uint32_t c : recent) {
        if (c == kNone || !allowed[c]) continue;
        if (blocksAll(c, 0)) {
          markUsed(c);
          if (byFirst) *byFirst = first;
          return true;
        }
        first = false;
      }
      // The first line collects candidates front to back through the
      // kD-tree; each is checked against the remaining lines at once, so
      // the traversal stops at the first occluder that blocks them all.
      const glm::dvec3 a0 = lineEnds(lines[0]).first, b0 = lineEnds(lines[0]).second;
      ++stats.linesCast;
      stats.linesCast += lines.size() - 1;
      uint32_t winner = kNone;
      forEachBlocker(a0, b0, tests, [&](uint32_t i) {
        if (blocksAll(i, 1)) {
          winner = i;
          return false;
        }
        first = false;
        return true;
      });
      if (winner == kNone) return false;
      markUsed(winner);
      if (byFirst) *byFirst = first;
      return true;
    }
    // Without the incremental set every line traverses the space on its own;
    // the answer is the intersection of the per-line sets.
    for (size_t l = 0; l < lines.size(); ++l) {
      const auto [a, b] = lineEnds(lines[l]);
      collect(a, b, tests, found);
      std::sort(found.begin(), found.end());
      if (l == 0) {
        candidates = found;
      } else {
        survivors.clear();
        std::set_intersection(candidates.begin(), candidates.end(), found.begin(), found.end(),
                              std::back_inserter(survivors));
        candidates.swap(survivors);
      }
      if (candidates.empty()) return false;
    }
    markUsed(candidates.front());
    if (byFirst) *byFirst = false;
    return true;
  }
};

bool EpsilonPvs::boxHidden(const Box3f& cell, const Box3f& box) const {
  PvsStats stats;
  const PvsOptions options;
  PvsQuery q(*this, options, cell, stats);
  std::array<glm::dvec3, 8> corners;
  for (int s = 0; s < 8; ++s) corners[size_t(s)] = cellCorner(box, s);
  std::array<std::pair<uint8_t, uint8_t>, 8> pairs;
  for (int s = 0; s < 8; ++s) pairs[size_t(s)] = {uint8_t(s), uint8_t(s)};
  uint64_t tests = 0;
  return q.hidden(corners, pairs, tests, nullptr);
}

PvsResult EpsilonPvs::compute(const Box3f& cell, const PvsOptions& options) const {
  Stopwatch total;
  PvsResult result;
  PvsStats& stats = result.stats;
  PvsQuery q(*this, options, cell, stats);

  // Every line pair between the cell's 8 corners and n points.
  static const auto allPairs = [] {
    std::vector<std::pair<uint8_t, uint8_t>> v;
    for (int k = 0; k < 255; ++k)
      for (int s = 0; s < 8; ++s) v.emplace_back(uint8_t(s), uint8_t(k));
    return v;
  }();
  static const auto boxPairs = [] {
    std::vector<std::pair<uint8_t, uint8_t>> v;
    for (int s = 0; s < 8; ++s) v.emplace_back(uint8_t(s), uint8_t(s));
    return v;
  }();

  // Near to far, so that hidden near objects stop serving as occluders early.
  const glm::vec3 centre = cell.center();
  std::vector<uint32_t> order(objects_.size());
  std::iota(order.begin(), order.end(), 0u);
  std::vector<float> dist(objects_.size());
  for (size_t i = 0; i < objects_.size(); ++i) {
    const Box3f& b = objects_[i].bounds;
    const glm::vec3 d = glm::max(glm::max(b.lo - centre, centre - b.hi), glm::vec3(0.0f));
    dist[i] = glm::dot(d, d);
  }
  std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return dist[a] < dist[b]; });

  std::vector<uint8_t> objectHidden(objects_.size(), 0);
  // Coarse to fine: the objects owning a candidate face; the others are
  // hidden already and only counted (in their turn, so that the occluders
  // they drop are dropped at the same point as if they were visited).
  std::vector<uint8_t> hasCandidate;
  if (options.candidateFaces) {
    hasCandidate.assign(objects_.size(), 0);
    for (uint32_t f : *options.candidateFaces)
      if (f < faceIndex_.size() && faceIndex_[f].first != ~0u)
        hasCandidate[faceIndex_[f].first] = 1;
  }
  auto isCandidate = [&](uint32_t face) {
    return !options.candidateFaces ||
           std::binary_search(options.candidateFaces->begin(), options.candidateFaces->end(), face);
  };

  // Solids fused within a plane, for the faces no single occluder hides,
  // where no occlusion horizons follow (PvsOptions::planarFusion).
  const bool horizonsFollow = options.fusion && fusion_;
  PlanarFusion::CellPlanes planes = options.planarFusion && planar_ && !horizonsFollow
                                        ? planar_->planesFor(cell)
                                        : PlanarFusion::CellPlanes{};
  const CellSupport support(cell);
  auto faceAway = [&](const Face& f) {
    return f.solid != kNoHit && facesAway(f, cell, support, solidFloor_[f.solid]);
  };

  double boxMs = 0.0, faceMs = 0.0;
  for (uint32_t idx : order) {
    const ObjectEntry& e = objects_[idx];
    stats.faces += e.faces.size();
    if (e.dynamic) {
      for (const Face& f : e.faces) result.faces.push_back(f.id);
      continue;
    }
    if (options.candidateFaces && !hasCandidate[idx]) {
      stats.facesOccluded += e.faces.size();
      objectHidden[idx] = 1;
      if (options.dropOccludedOccluders)
        for (uint32_t oc : occludersOf_[e.object]) q.allowed[oc] = 0;
      continue;
    }
    bool anyVisible = false;
    for (const OccludeeGroup& g : e.groups) {
      if (options.candidateFaces) {
        // Coarse to fine: a group with no face in the coarse PVS is hidden already.
        bool any = false;
        for (uint32_t fi = g.firstFace; fi < g.firstFace + g.faceCount && !any; ++fi)
          any = isCandidate(e.faces[fi].id);
        if (!any) {
          stats.facesOccluded += g.faceCount;
          continue;
        }
      }
      if (options.backFaces) {
        // A group facing away from the cell entirely needs no box stage
        // (the first face that does not settles it).
        bool allAway = true;
        for (uint32_t fi = g.firstFace; fi < g.firstFace + g.faceCount && allAway; ++fi)
          allAway = faceAway(e.faces[fi]);
        if (allAway) {
          stats.facesBackFacing += g.faceCount;
          stats.facesOccluded += g.faceCount;
          continue;
        }
      }
      if (options.boxStage) {
        Stopwatch sw;
        ++stats.boxes;
        stats.objectBoxes += e.groups.size() == 1;
        bool byFirst = false;
        bool boxHidden = q.hidden(
            g.boxCorners,
            options.removeRedundantLines ? std::span(boxPairs) : std::span(allPairs).first(64),
            stats.lineBoxTests, &byFirst);
        // Solids fused in a plane may hide the whole box (then each face
        // of it, whose footprint lies in the box's).
        if (!boxHidden && !planes.empty() && planar_->hidden(cell, planes, g.boxCorners)) {
          boxHidden = true;
          stats.facesPlanar += g.faceCount;
        }
        boxMs += sw.ms();
        if (boxHidden) {
          ++stats.boxesOccluded;
          stats.boxesOccludedByFirst += byFirst;
          if (e.groups.size() == 1) {
            ++stats.objectBoxesOccluded;
            stats.objectBoxesOccludedByFirst += byFirst;
          }
          stats.facesCulledByBoxStage += g.faceCount;
          stats.facesOccluded += g.faceCount;
          continue;
        }
      }
      Stopwatch sw;
      for (uint32_t fi = g.firstFace; fi < g.firstFace + g.faceCount; ++fi) {
        const Face& f = e.faces[fi];
        if (!isCandidate(f.id)) {
          ++stats.facesOccluded;
          continue;
        }
        if (options.faceless && !f.hasArea) {
          ++stats.facesWithoutArea;
          ++stats.facesOccluded;
          continue;
        }
        if (options.backFaces && faceAway(f)) {
          ++stats.facesBackFacing;
          ++stats.facesOccluded;
          continue;
        }
        const bool reduced = options.removeRedundantLines && !f.keptLines.empty();
        const std::span<const std::pair<uint8_t, uint8_t>> lines =
            reduced ? std::span(f.keptLines)
                    : std::span(allPairs).first(8 * std::min<size_t>(f.vertices.size(), 255));
        if (f.vertices.size() <= 255 &&
            q.hidden(f.vertices, lines, stats.linePolygonTests, nullptr)) {
          ++stats.facesOccluded;
        } else if (!planes.empty() && planar_->hidden(cell, planes, f.vertices)) {
          ++stats.facesPlanar;
          ++stats.facesOccluded;
        } else {
          result.faces.push_back(f.id);
          anyVisible = true;
        }
      }
      faceMs += sw.ms();
    }
    // A hidden object hides nothing that its occluders would: drop them.
    if (!anyVisible) {
      objectHidden[idx] = 1;
      if (options.dropOccludedOccluders)
        for (uint32_t oc : occludersOf_[e.object]) q.allowed[oc] = 0;
    }
  }

  std::sort(result.faces.begin(), result.faces.end());
  result.faces.erase(std::unique(result.faces.begin(), result.faces.end()), result.faces.end());
  // Occluder fusion on what one occluder could not hide.
  if (options.fusion && fusion_) {
    Stopwatch sw;
    HorizonFusionResult fused = fusion_->cull(cell, result.faces);
    stats.facesFused = result.faces.size() - fused.faces.size();
    stats.facesOccluded += stats.facesFused;
    result.faces = std::move(fused.faces);
    stats.fusionMs = sw.ms();
  }
  // Objects with a face in the PVS.
  std::vector<uint8_t> hasFace(objects_.size(), 0);
  for (uint32_t f : result.faces)
    if (f < faceIndex_.size() && faceIndex_[f].first != ~0u) hasFace[faceIndex_[f].first] = 1;
  for (uint32_t e = 0; e < objects_.size(); ++e)
    if (hasFace[e]) result.objects.push_back(objects_[e].object);
  stats.occludersUsed = size_t(std::count(q.used.begin(), q.used.end(), uint8_t(1)));
  stats.boxStageMs = boxMs;
  stats.faceStageMs = faceMs;
  stats.timeMs = total.ms();
  return result;
}

}  // namespace vistream
