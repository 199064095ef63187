// Occlusion tree and its node visibility test, after Bittner, Havran and Slavik
// 1998 ("Hierarchical visibility culling with occlusion trees", CGI'98) as
// summarised in "The Node Visibility Test", section "Overview", of Bittner and
// Havran 2001 ("Exploiting coherence in hierarchical visibility algorithms"):
// "an occlusion tree, which results from merging 'shadow' frusta of each
// individual occluder ... a BSP tree which has its leaves classified as in or
// out ... The node visibility test is performed using constrained depth first
// search (DFS) on the occlusion tree."
//
// Why the insertion below is exact, and how rounding is kept conservative.
// All geometry is relative to the viewpoint V (so every shadow plane passes
// through the origin, and far-from-origin scenes lose no precision). Every
// 'out' leaf's cell C is convex with V in its closure: its planes either pass
// through V (shadow planes) or have V strictly in front (occluder planes, whose
// back side is always an 'in' leaf). Hence for p in C the whole segment V->p
// lies in closure(C), and for any occluder F and any fragment F' with
// F cut closure(C) <= F' <= F:  C cut shadow(F) = C cut shadow(F').
// Two consequences:
//  - routing a fragment into more cells than it really reaches never adds
//    wrong shadow, while missing a cell loses shadow. So a fragment goes to
//    each side of a node plane that it comes within the tolerance of, cut by
//    the plane shifted by the tolerance towards the other side;
//  - at a leaf, the shadow subtree needs the polygon's plane and the planes
//    through V and those of the polygon's edges that cut the cell; edges the
//    cell already implies (shared with earlier occluders, typically) are left
//    out, which is what makes the fusion across shared edges and corners
//    watertight for the DFS below. The planes are computed once per polygon
//    from its input vertices, never from cut fragments, so cutting adds no
//    rounding to the tree's planes.
// The DFS treats a box within the tolerance of a plane as straddling it, so a
// box's tolerance neighbourhood lies in the union of the leaf cells it reaches:
// 'all in' then means the box is strictly inside the fused shadow, 'all out'
// that it meets no shadow at all.
#include "server/visibility/occlusion_tree.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <utility>

namespace vistream {
namespace {

// Distances below kRelativeTolerance * (1 + coordinate magnitude) count as
// zero: about 1e7 times the rounding error of double arithmetic on such
// coordinates, and far below anything visible (0.01 mm at 10 km).
constexpr double kRelativeTolerance = 1e-9;
// A polygon whose area is below this fraction of its squared size is a
// sliver or a collinear chain: it casts no shadow worth a tree node.
constexpr double kMinRelativeArea = 1e-10;
// Rounding error of the cell cross-sections used to prune implied edge
// planes, relative to 1 + coordinate magnitude: ~1e4 times double rounding,
// 1e-3 of the tolerance, so a pruned plane moves a shadow boundary by far less
// than the tolerance for boxes up to ~1000 times farther than the occluder.
constexpr double kRoundingRelativeTolerance = 1e-12;

double tolerance(double magnitude) {
  return kRelativeTolerance * (1.0 + magnitude);
}

double maxAbs(const glm::dvec3& v) {
  return std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)});
}

// An occluder as seen from the viewpoint, in coordinates relative to it.
struct ShadowFrustum {
  std::vector<glm::dvec3> vertices;  // duplicates removed
  glm::dvec3 normal{0.0};            // unit, towards the viewpoint
  double offset = 0.0;               // plane dot(normal, x) = offset, offset < 0
  // Per edge i (vertices i -> i+1): the plane through the viewpoint and the
  // edge, unit normal pointing into the polygon's shadow (offset 0).
  std::vector<glm::dvec3> edgeNormals;
  double area = 0.0;
  glm::dvec3 centroid{0.0};  // vertex centroid
};

// The shadow frustum of a polygon, or nothing when the polygon is degenerate
// or seen edge-on (its plane within `tol` of the viewpoint).
std::optional<ShadowFrustum> shadowFrustumOf(const OccluderPolygon& polygon,
                                             const glm::dvec3& viewpoint, double tol) {
  ShadowFrustum f;
  for (const glm::dvec3& p : polygon.vertices) {
    const glm::dvec3 v = p - viewpoint;
    if (!f.vertices.empty() && glm::length(v - f.vertices.back()) <= tol) continue;
    f.vertices.push_back(v);
  }
  while (f.vertices.size() > 1 && glm::length(f.vertices.back() - f.vertices.front()) <= tol)
    f.vertices.pop_back();
  const size_t n = f.vertices.size();
  if (n < 3) return std::nullopt;

  // Newell's normal, relative to the first vertex for accuracy.
  const glm::dvec3 v0 = f.vertices[0];
  glm::dvec3 newell(0.0);
  double size2 = 0.0;
  for (size_t i = 1; i + 1 < n; ++i)
    newell += glm::cross(f.vertices[i] - v0, f.vertices[i + 1] - v0);
  for (size_t i = 1; i < n; ++i)
    size2 = std::max(size2, glm::dot(f.vertices[i] - v0, f.vertices[i] - v0));
  f.area = 0.5 * glm::length(newell);
  if (!(f.area > kMinRelativeArea * size2)) return std::nullopt;  // also rejects NaN

  f.normal = newell / (2.0 * f.area);
  glm::dvec3 centroid(0.0);
  for (const glm::dvec3& v : f.vertices) centroid += v;
  f.centroid = centroid / double(n);
  f.offset = glm::dot(f.normal, f.centroid);
  if (std::abs(f.offset) <= tol) return std::nullopt;  // edge-on: no shadow
  if (f.offset > 0.0) {
    f.normal = -f.normal;
    f.offset = -f.offset;
  }

  f.edgeNormals.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    glm::dvec3 m = glm::cross(f.vertices[i], f.vertices[(i + 1) % n]);
    const double len = glm::length(m);
    // The edge's line misses the viewpoint (which is off the polygon's plane),
    // so m != 0 unless the input is garbage.
    if (!(len > 0.0)) return std::nullopt;
    m /= len;
    if (glm::dot(m, f.centroid) < 0.0) m = -m;
    f.edgeNormals.push_back(m);
  }
  return f;
}

double largestMagnitude(const glm::dvec3& viewpoint, std::span<const OccluderPolygon> polygons) {
  double m = maxAbs(viewpoint);
  for (const OccluderPolygon& p : polygons)
    for (const glm::dvec3& v : p.vertices) m = std::max(m, maxAbs(v));
  return m;
}

// The part of a convex polygon where g >= 0, with g_i given per vertex and
// linear along edges (Sutherland-Hodgman against one plane).
using Polygon3 = std::vector<glm::dvec3>;
Polygon3 clip(const Polygon3& poly, const std::vector<double>& g) {
  Polygon3 out;
  const size_t n = poly.size();
  for (size_t i = 0; i < n; ++i) {
    const size_t j = (i + 1) % n;
    if (g[i] >= 0.0) out.push_back(poly[i]);
    if ((g[i] >= 0.0) != (g[j] >= 0.0)) {
      const double t = g[i] / (g[i] - g[j]);
      out.push_back(poly[i] + t * (poly[j] - poly[i]));
    }
  }
  return out;
}

// The part of a convex polygon on one side of the plane dot(normal, x) = offset.
Polygon3 clipToSide(const Polygon3& poly, const glm::dvec3& normal, double offset, bool front,
                    std::vector<double>& g) {
  g.resize(poly.size());
  for (size_t i = 0; i < poly.size(); ++i) {
    const double s = glm::dot(normal, poly[i]) - offset;
    g[i] = front ? s : -s;
  }
  return clip(poly, g);
}

double doubleArea(const Polygon3& poly) {
  glm::dvec3 sum(0.0);
  for (size_t i = 1; i + 1 < poly.size(); ++i)
    sum += glm::cross(poly[i] - poly[0], poly[i + 1] - poly[0]);
  return glm::length(sum);
}

}  // namespace

std::vector<size_t> selectOccluders(const glm::dvec3& viewpoint,
                                    std::span<const OccluderPolygon> candidates, size_t k) {
  std::vector<std::pair<double, size_t>> scored;
  for (size_t i = 0; i < candidates.size(); ++i) {
    const double tol = tolerance(largestMagnitude(viewpoint, candidates.subspan(i, 1)));
    const std::optional<ShadowFrustum> f = shadowFrustumOf(candidates[i], viewpoint, tol);
    if (!f) continue;
    // area * |cos| / d^2 with cos = dot(normal, c) / d and d = |c|.
    const double d = glm::length(f->centroid);
    scored.emplace_back(f->area * std::abs(glm::dot(f->normal, f->centroid)) / (d * d * d), i);
  }
  std::stable_sort(scored.begin(), scored.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<size_t> chosen;
  for (size_t i = 0; i < scored.size() && i < k; ++i) chosen.push_back(scored[i].second);
  return chosen;
}

OcclusionTree::OcclusionTree(const glm::dvec3& viewpoint,
                             std::span<const OccluderPolygon> occluders)
    : viewpoint_(viewpoint), magnitude_(largestMagnitude(viewpoint, occluders)) {
  const double tol = tolerance(magnitude_);
  // Slack for deciding that an edge plane is implied by a cell: only rounding
  // error, far below the tolerance (see the edge pruning below).
  const double roundingSlack = kRoundingRelativeTolerance * (1.0 + magnitude_);

  // A fragment waiting to be inserted at a child link: the link's owner
  // node, or -1 for the root.
  struct Pending {
    int32_t owner;
    bool front;
    Polygon3 fragment;
  };
  // Per node, the link it hangs from (owner * 2 + (front ? 1 : 0)), or -1 at
  // the root: the planes bounding a leaf's cell, walked upwards.
  std::vector<int32_t> parentLink;
  std::vector<Pending> pending;
  std::vector<double> s, g;
  std::vector<uint32_t> keptEdges;

  for (const OccluderPolygon& polygon : occluders) {
    const std::optional<ShadowFrustum> frustum = shadowFrustumOf(polygon, viewpoint_, tol);
    if (!frustum) continue;
    ++occluderCount_;
    const ShadowFrustum& f = *frustum;

    // A square in the polygon's plane around the polygon, twice its radius:
    // the start of each cell's cross-section below.
    double radius = 0.0;
    for (const glm::dvec3& v : f.vertices) radius = std::max(radius, glm::length(v - f.centroid));
    const glm::dvec3 axis = std::abs(f.normal.x) < 0.6 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
    const glm::dvec3 u = 2.0 * radius * glm::normalize(glm::cross(f.normal, axis));
    const glm::dvec3 w = glm::cross(f.normal, u);
    const Polygon3 square = {f.centroid - u - w, f.centroid + u - w, f.centroid + u + w,
                             f.centroid - u + w};

    pending.push_back({-1, false, f.vertices});
    while (!pending.empty()) {
      Pending item = std::move(pending.back());
      pending.pop_back();
      const int32_t link = item.owner < 0
                               ? root_
                               : (item.front ? nodes_[item.owner].front : nodes_[item.owner].back);
      if (link == kInLeaf) continue;  // already hidden, and so is its shadow

      if (link == kOutLeaf) {
        // Replace the leaf by the occluder's shadow frustum restricted to the
        // leaf's cell C. The polygon's plane (behind -> in) is always needed;
        // an edge plane only where it cuts C. Edges shared with earlier
        // occluders are the common case of an implied edge: building their
        // plane again would leave a cell of zero width beside it, which a box
        // straddling the plane reaches, and that spurious 'out' would undo
        // the fusion across the shared edge (or corner).
        // The test: the cross-section R of C with the polygon's plane (within
        // the square), clipped by the edges kept so far, lies on the inner
        // side of the edge's line up to rounding. Then every segment from the
        // viewpoint to a point of C behind the plane meets the plane in R,
        // hence inside the polygon once R is clipped by the kept edges (the
        // cell is a cone from the viewpoint). If R is empty or thinner than
        // the rounding slack, before or after the clipping, C holds no shadow
        // of this polygon (C is open, so its shadow would cross the plane in
        // a region of positive area) and the leaf stays 'out': a chain there
        // would only make a cell of zero width.
        const double minDoubleArea = roundingSlack * radius;
        auto degenerate = [minDoubleArea](const Polygon3& poly) {
          return poly.size() < 3 || !(doubleArea(poly) > minDoubleArea);
        };
        Polygon3 section = square;
        for (int32_t up = item.owner * 2 + (item.front ? 1 : 0); up >= 0 && !degenerate(section);) {
          const Node& bound = nodes_[size_t(up / 2)];
          section = clipToSide(section, bound.normal, bound.offset, up % 2 == 1, g);
          up = parentLink[size_t(up / 2)];
        }
        keptEdges.clear();
        for (uint32_t e = 0; e < f.edgeNormals.size() && !degenerate(section); ++e) {
          bool implied = true;
          for (const glm::dvec3& x : section)
            implied = implied && glm::dot(f.edgeNormals[e], x) >= -roundingSlack;
          if (implied) continue;
          section = clipToSide(section, f.edgeNormals[e], 0.0, true, g);
          keptEdges.push_back(e);
        }
        if (degenerate(section)) continue;

        // The chain: one node per kept edge (outside -> out), then the
        // polygon's plane (in front -> out, behind -> in).
        const int32_t first = int32_t(nodes_.size());
        const int32_t parent = item.owner < 0 ? -1 : item.owner * 2 + (item.front ? 1 : 0);
        for (uint32_t e : keptEdges) {
          const int32_t id = int32_t(nodes_.size());
          nodes_.push_back({f.edgeNormals[e], 0.0, id + 1, kOutLeaf});
          parentLink.push_back(id == first ? parent : (id - 1) * 2 + 1);
        }
        const int32_t planeId = int32_t(nodes_.size());
        nodes_.push_back({f.normal, f.offset, kOutLeaf, kInLeaf});
        parentLink.push_back(planeId == first ? parent : (planeId - 1) * 2 + 1);
        if (item.owner < 0) {
          root_ = first;
        } else if (item.front) {
          nodes_[item.owner].front = first;
        } else {
          nodes_[item.owner].back = first;
        }
        continue;
      }

      // An interior node: send the fragment to every side it comes within
      // the tolerance of, cut by the plane shifted by the tolerance.
      const Node node = nodes_[size_t(link)];
      const Polygon3& fragment = item.fragment;
      s.resize(fragment.size());
      bool anyFront = false, anyBack = false, allFront = true, allBack = true;
      for (size_t i = 0; i < fragment.size(); ++i) {
        s[i] = glm::dot(node.normal, fragment[i]) - node.offset;
        anyFront = anyFront || s[i] > -tol;
        anyBack = anyBack || s[i] < tol;
        allFront = allFront && s[i] >= -tol;
        allBack = allBack && s[i] <= tol;
      }
      g.resize(s.size());
      if (anyBack && node.back != kInLeaf) {
        if (allBack) {
          pending.push_back({link, false, fragment});
        } else {
          for (size_t i = 0; i < s.size(); ++i) g[i] = tol - s[i];
          pending.push_back({link, false, clip(fragment, g)});
        }
      }
      if (anyFront && node.front != kInLeaf) {
        if (allFront) {
          pending.push_back({link, true, std::move(item.fragment)});
        } else {
          for (size_t i = 0; i < s.size(); ++i) g[i] = s[i] + tol;
          pending.push_back({link, true, clip(fragment, g)});
        }
      }
    }
  }
}

namespace {

// A half-space dot(normal, x) - offset >= -tol (the side a DFS entered).
struct HalfSpace {
  glm::dvec3 normal;
  double offset;
};

// Whether the box [lo, hi] meets every half-space, each widened by tol. The
// set they cut out of the box is a convex polytope; it is non-empty exactly
// when one of its facets is, and every facet lies on a box face or on one of
// the half-spaces' planes: so clip each of those polygons by all the others.
bool boxMeetsHalfSpaces(const glm::dvec3& lo, const glm::dvec3& hi,
                        const std::vector<HalfSpace>& cuts, double tol) {
  std::vector<HalfSpace> all = cuts;
  for (int axis = 0; axis < 3; ++axis) {
    glm::dvec3 n(0.0);
    n[axis] = 1.0;
    all.push_back({n, lo[axis]});    // x >= lo
    all.push_back({-n, -hi[axis]});  // x <= hi
  }
  const glm::dvec3 centre = 0.5 * (lo + hi);
  const double size = 2.0 * glm::length(hi - lo) + 1.0;
  std::vector<double> g;
  for (size_t j = 0; j < all.size(); ++j) {
    // A square on plane j around the box centre's projection, larger than the box.
    const glm::dvec3 n = all[j].normal;
    const glm::dvec3 c = centre - (glm::dot(n, centre) - all[j].offset) * n;
    const glm::dvec3 a = glm::normalize(std::abs(n.x) < 0.9 ? glm::cross(n, glm::dvec3(1, 0, 0))
                                                            : glm::cross(n, glm::dvec3(0, 1, 0)));
    const glm::dvec3 b = glm::cross(n, a);
    Polygon3 poly = {c - size * a - size * b, c + size * a - size * b, c + size * a + size * b,
                     c - size * a + size * b};
    for (size_t i = 0; i < all.size() && !poly.empty(); ++i) {
      if (i == j) continue;
      g.resize(poly.size());
      for (size_t v = 0; v < poly.size(); ++v)
        g[v] = glm::dot(all[i].normal, poly[v]) - all[i].offset + tol;
      poly = clip(poly, g);
    }
    if (!poly.empty()) return true;
  }
  return false;
}

}  // namespace

NodeVisibility OcclusionTree::classifyRelative(const glm::dvec3& lo, const glm::dvec3& hi,
                                               double tol, uint64_t* nodesVisited) const {
  const glm::dvec3 centre = 0.5 * (lo + hi);
  const glm::dvec3 halfExtent = 0.5 * (hi - lo);

  // Constrained DFS: a box reaches the side(s) of a plane it comes within the
  // tolerance of; stop once both leaf kinds have been reached. Testing one
  // plane at a time over-reaches: a box that straddles two planes on the way
  // down can reach a leaf whose cell it misses. So the planes a box straddles
  // are kept, and a leaf reached past two or more of them counts only if the
  // box really meets its cell (within the tolerance).
  bool reachedIn = false, reachedOut = false;
  uint64_t visited = 0;
  std::vector<HalfSpace> straddled;
  auto visit = [&](auto&& self, int32_t id) -> void {
    if (reachedIn && reachedOut) return;
    ++visited;
    if (id == kInLeaf || id == kOutLeaf) {
      bool& reached = id == kInLeaf ? reachedIn : reachedOut;
      if (!reached && (straddled.size() < 2 || boxMeetsHalfSpaces(lo, hi, straddled, tol)))
        reached = true;
      return;
    }
    const Node& node = nodes_[size_t(id)];
    const double s = glm::dot(node.normal, centre) - node.offset;
    const double r = glm::dot(glm::abs(node.normal), halfExtent);
    const bool front = s + r >= -tol, back = s - r <= tol;
    if (front && back) {
      straddled.push_back({node.normal, node.offset});
      self(self, node.front);
      straddled.back() = {-node.normal, -node.offset};
      self(self, node.back);
      straddled.pop_back();
    } else if (front) {
      self(self, node.front);
    } else if (back) {
      self(self, node.back);
    }
  };
  visit(visit, root_);
  if (nodesVisited) *nodesVisited += visited;

  if (!reachedIn) return NodeVisibility::Visible;
  if (reachedOut) return NodeVisibility::PartiallyVisible;
  // The viewpoint is never in shadow; the DFS already reaches an 'out' leaf
  // for any box within the tolerance of it, this keeps the promise explicit.
  const bool nearViewpoint = glm::all(glm::lessThanEqual(lo, glm::dvec3(tol))) &&
                             glm::all(glm::greaterThanEqual(hi, glm::dvec3(-tol)));
  return nearViewpoint ? NodeVisibility::PartiallyVisible : NodeVisibility::Invisible;
}

NodeVisibility OcclusionTree::classify(const Box3f& box, uint64_t* nodesVisited) const {
  // An empty box has no point in shadow; answering Visible never culls anything.
  if (box.empty()) return NodeVisibility::Visible;
  const glm::dvec3 lo(box.lo), hi(box.hi);
  const double tol = tolerance(std::max({magnitude_, maxAbs(lo), maxAbs(hi)}));
  return classifyRelative(lo - viewpoint_, hi - viewpoint_, tol, nodesVisited);
}

bool OcclusionTree::inShadow(const glm::dvec3& p) const {
  const double tol = tolerance(std::max(magnitude_, maxAbs(p)));
  const glm::dvec3 q = p - viewpoint_;
  return classifyRelative(q, q, tol, nullptr) == NodeVisibility::Invisible;
}

}  // namespace vistream
