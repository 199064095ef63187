// Occluder fusion within a plane; the proof is in planar_fusion.h.
#include "server/visibility/planar_fusion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <span>

#include "common/spatial/convex_hull.h"
#include "common/spatial/convex_polygon.h"

namespace vistream {
namespace {

// True if p lies in the counter-clockwise convex polygon grown by `slack`.
bool insidePiece(const std::vector<glm::dvec2>& poly, const glm::dvec2& p, double slack) {
  for (size_t i = 0; i < poly.size(); ++i) {
    const glm::dvec2& a = poly[i];
    const glm::dvec2 e = poly[(i + 1) % poly.size()] - a;
    if (e.x * (p.y - a.y) - e.y * (p.x - a.x) < -slack * glm::length(e)) return false;
  }
  return true;
}

// Replaces two pieces by their convex hull where the two cover the hull
// but for strips narrower than `slack` (the seam the shrinking opens
// between abutting solids: coveredBy): a row of wall patches becomes one
// rectangle, so a footprint is tested against a few pieces instead of many.
// The pieces come out in order of lowest u (a merged piece keeps the lowest
// u of the first of its parts), as PlanarFusion::hidden searches them.
void mergePieces(std::vector<std::vector<glm::dvec2>>& pieces, std::vector<glm::dvec4>& bounds,
                 double slack) {
  // Merging only saves work later (coverage is decided by coveredBy over
  // whatever pieces there are), so one sweep in order of lowest u, each
  // piece absorbing the later ones it can while their u ranges meet, is
  // enough: O(n log n + merges) for a street of facades instead of
  // restarting after every merge.
  std::vector<size_t> order(pieces.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return bounds[a].x < bounds[b].x; });
  std::vector<std::vector<glm::dvec2>> out;
  std::vector<glm::dvec4> outBounds;
  std::vector<uint8_t> gone(pieces.size(), 0);
  std::vector<glm::dvec2> both;
  for (size_t a = 0; a < order.size(); ++a) {
    const size_t i = order[a];
    if (gone[i]) continue;
    std::vector<glm::dvec2> piece = std::move(pieces[i]);
    glm::dvec4 box = bounds[i];
    for (size_t b = a + 1; b < order.size() && bounds[order[b]].x <= box.z + slack; ++b) {
      const size_t j = order[b];
      if (gone[j]) continue;
      const glm::dvec4 grown = box + glm::dvec4(-slack, -slack, slack, slack);
      if (!rectsOverlap(grown, bounds[j])) continue;
      both = piece;
      both.insert(both.end(), pieces[j].begin(), pieces[j].end());
      std::vector<glm::dvec2> hull = convexHull2d(both);
      if (hull.size() < 3) continue;
      const std::vector<glm::dvec2> two[2] = {piece, pieces[j]};
      const glm::dvec4 twoBounds[2] = {box, bounds[j]};
      if (!coveredBy(hull, two, twoBounds, slack)) continue;
      piece = std::move(hull);
      box = polygonBounds(piece);
      gone[j] = 1;
    }
    out.push_back(std::move(piece));
    outBounds.push_back(box);
  }
  pieces = std::move(out);
  bounds = std::move(outBounds);
}

}  // namespace

PlanarFusion::PlanarFusion(const OccluderSet& occluders) {
  // Every face plane of every solid occluder, by normal then offset.
  struct Entry {
    glm::dvec3 n;
    double d;
    uint32_t occluder;
  };
  std::vector<Entry> entries;
  double magnitude = 0.0;
  for (size_t i = 0; i < occluders.occluders.size(); ++i) {
    const ConvexOccluder& o = occluders.occluders[i];
    if (o.kind != ConvexOccluder::Kind::Solid) continue;
    magnitude =
        std::max({magnitude, double(glm::length(o.bounds.lo)), double(glm::length(o.bounds.hi))});
    for (const glm::dvec4& p : o.planes) entries.push_back({glm::dvec3(p), p.w, uint32_t(i)});
  }
  const double tolerance = 1e-6 * (1.0 + magnitude);
  // A slab depth far above rounding, far below any wall's thickness.
  const double e = std::max(1e-3, 1e-6 * (1.0 + magnitude));
  auto key = [](const glm::dvec3& n) {
    return glm::dvec3(std::round(n.x * 1e9), std::round(n.y * 1e9), std::round(n.z * 1e9));
  };
  std::sort(entries.begin(), entries.end(), [&](const Entry& a, const Entry& b) {
    const glm::dvec3 ka = key(a.n), kb = key(b.n);
    if (ka.x != kb.x) return ka.x < kb.x;
    if (ka.y != kb.y) return ka.y < kb.y;
    if (ka.z != kb.z) return ka.z < kb.z;
    return a.d < b.d;
  });
  std::vector<glm::dvec2> poly, tmp;
  for (size_t i = 0; i < entries.size();) {
    // One plane: the same normal, offsets chained within the tolerance.
    size_t j = i + 1;
    while (j < entries.size() && key(entries[j].n) == key(entries[i].n) &&
           entries[j].d - entries[j - 1].d <= tolerance)
      ++j;
    if (j - i < 2) {  // one face alone fuses nothing
      i = j;
      continue;
    }
    Plane pl;
    pl.n = glm::normalize(entries[i].n);
    const glm::dvec3 axis = std::abs(pl.n.x) < 0.6 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
    pl.u = glm::normalize(glm::cross(pl.n, axis));
    pl.v = glm::cross(pl.n, pl.u);
    pl.top = entries[i].d - e;  // the smallest offset comes first
    pl.bottom = pl.top - e;
    double planeMagnitude = 0.0;
    for (size_t k = i; k < j; ++k) {
      const ConvexOccluder& o = occluders.occluders[entries[k].occluder];
      // Q: the points (a, b) at height top whose segment down to bottom
      // lies in the region, from a square around the occluder's bounds.
      const glm::dvec3 lo(o.bounds.lo), hi(o.bounds.hi);
      const double r = glm::length(hi - lo) + 1.0;
      const glm::dvec3 c = 0.5 * (lo + hi);
      const double cu = glm::dot(c, pl.u), cv = glm::dot(c, pl.v);
      poly = {{cu - r, cv - r}, {cu + r, cv - r}, {cu + r, cv + r}, {cu - r, cv + r}};
      for (const glm::dvec4& h : o.planes) {
        const glm::dvec3 hn(h);
        const double a = glm::dot(hn, pl.u), b = glm::dot(hn, pl.v), w = glm::dot(hn, pl.n);
        // hn . (a u + b v + t n) < h.w at t = top and t = bottom.
        const double limit = h.w - std::max(w * pl.top, w * pl.bottom);
        if (std::abs(a) < 1e-12 && std::abs(b) < 1e-12) {
          if (!(0.0 < limit)) poly.clear();
        } else {
          clipToHalfPlane(poly, tmp, a, b, limit);
        }
        if (poly.empty()) break;
      }
      if (poly.size() < 3 || !(twiceArea(poly) > 0.0)) continue;
      pl.pieceBounds.push_back(polygonBounds(poly));
      for (const glm::dvec2& q : poly) {
        const glm::dvec3 x = q.x * pl.u + q.y * pl.v + pl.top * pl.n;
        pl.bounds.extend(glm::vec3(x));
        planeMagnitude = std::max(planeMagnitude, glm::length(x));
      }
      pl.pieces.push_back(poly);
    }
    if (pl.pieces.size() >= 2) {
      pl.margin = occluderMargin(planeMagnitude);
      mergePieces(pl.pieces, pl.pieceBounds, 4.0 * pl.margin);
      for (const glm::dvec4& b : pl.pieceBounds) pl.widest = std::max(pl.widest, b.z - b.x);
      // Grown by the float rounding of the bounds.
      pl.bounds.lo -= glm::vec3(float(1e-5 * (1.0 + planeMagnitude)));
      pl.bounds.hi += glm::vec3(float(1e-5 * (1.0 + planeMagnitude)));
      planes_.push_back(std::move(pl));
    }
    i = j;
  }
  // The pieces by X/Z cell (a plane's bounds can span a whole street of
  // facades, its pieces do not); a grid item is a piece, pieceOwner_ names
  // its plane. Each box holds its piece's bounds grown by the slack the
  // point tests allow (they accept nothing beyond: hidden()), and more for
  // the float rounding of the box and of the walk along the grid (100
  // margins, as the plane's bounds) and a millimetre.
  std::vector<Box3f> boxes;
  Box3f all;
  for (size_t i = 0; i < planes_.size(); ++i) {
    const Plane& pl = planes_[i];
    const float grow = float(100.0 * pl.margin) + 1e-3f;
    for (const std::vector<glm::dvec2>& piece : pl.pieces) {
      Box3f b;
      const glm::dvec4& pb = pl.pieceBounds[size_t(&piece - pl.pieces.data())];
      const double slack = 4.0 * pl.margin;
      for (const glm::dvec2 q :
           {glm::dvec2(pb.x - slack, pb.y - slack), glm::dvec2(pb.z + slack, pb.y - slack),
            glm::dvec2(pb.z + slack, pb.w + slack), glm::dvec2(pb.x - slack, pb.w + slack)})
        b.extend(glm::vec3(q.x * pl.u + q.y * pl.v + pl.top * pl.n));
      b.lo -= glm::vec3(grow);
      b.hi += glm::vec3(grow);
      boxes.push_back(b);
      pieceOwner_.push_back(uint32_t(i));
      all.extend(b);
    }
  }
  // Grid cells of 8 m (more on scenes wider than 8 km): a line crosses a
  // quarter of the cells it would at 2 m, and each cell's list of planes
  // in front (CellPlanes) is read once per view cell, so longer lists cost
  // little (bigcity, 4 m view cells: 2 m 225 ms a cell, 6 m 208, 8 m 192,
  // 12 m 195-200, 24 m 244).
  if (!all.empty()) {
    const float extent = std::max(all.hi.x - all.lo.x, all.hi.z - all.lo.z);
    grid_ = XzGrid(all, std::max(extent / 1024.0f, 8.0f), boxes);
  }
}

PlanarFusion::CellPlanes PlanarFusion::planesFor(const Box3f& cell) const {
  CellPlanes out;
  out.inFront.assign(planes_.size(), 0);
  const glm::dvec3 centre(cell.center()), half(0.5 * (glm::dvec3(cell.hi) - glm::dvec3(cell.lo)));
  for (size_t i = 0; i < planes_.size(); ++i) {
    const Plane& p = planes_[i];
    // The lowest height of a cell point along n, above the slab's top.
    const double lowest = glm::dot(p.n, centre) - glm::dot(glm::abs(p.n), half);
    if (lowest > p.top + p.margin) {
      out.inFront[i] = 1;
      ++out.count;
    }
  }
  return out;
}

bool PlanarFusion::hidden(const Box3f& cell, CellPlanes& cellPlanes,
                          std::span<const glm::dvec3> vertices) const {
  if (vertices.empty()) return false;
  Box3f shaft = cell;
  for (const glm::dvec3& p : vertices) shaft.extend(glm::vec3(p));
  glm::dvec3 corners[8];
  for (int k = 0; k < 8; ++k) corners[k] = glm::dvec3(cell.corner(k));
  thread_local std::vector<glm::dvec2> points;
  // Candidates: the planes of the grid cells the X/Z segment from the
  // cell's centre to the first vertex passes through (a 2D DDA), each once.
  thread_local std::vector<uint32_t> candidates, stamp;
  thread_local uint32_t query = 0;
  candidates.clear();
  if (stamp.size() != planes_.size()) {
    stamp.assign(planes_.size(), 0);
    query = 0;
  }
  if (++query == 0) {  // wrapped: start the stamps again
    std::fill(stamp.begin(), stamp.end(), 0);
    query = 1;
  }
  if (grid_.empty()) return false;
  const glm::ivec2 dims = grid_.dims();
  if (cellPlanes.slot.size() != size_t(dims.x) * size_t(dims.y))
    cellPlanes.slot.assign(size_t(dims.x) * size_t(dims.y), 0);
  auto collect = [&](glm::ivec2 at) {
    uint32_t& slot = cellPlanes.slot[size_t(at.y) * size_t(dims.x) + size_t(at.x)];
    if (slot == 0) {
      std::vector<uint32_t>& lists = cellPlanes.lists;
      const size_t begin = lists.size();
      for (uint32_t piece : grid_.itemsIn(at))
        if (const uint32_t i = pieceOwner_[piece]; cellPlanes.inFront[i]) lists.push_back(i);
      std::sort(lists.begin() + ptrdiff_t(begin), lists.end());
      lists.erase(std::unique(lists.begin() + ptrdiff_t(begin), lists.end()), lists.end());
      cellPlanes.ranges.emplace_back(uint32_t(begin), uint32_t(lists.size()));
      slot = uint32_t(cellPlanes.ranges.size());
    }
    const auto [from, to] = cellPlanes.ranges[slot - 1];
    for (uint32_t k = from; k < to; ++k)
      if (const uint32_t i = cellPlanes.lists[k]; stamp[i] != query) {
        stamp[i] = query;
        candidates.push_back(i);
      }
  };
  {
    const glm::vec3 c = cell.center();
    const glm::vec2 a(c.x, c.z), b(float(vertices[0].x), float(vertices[0].z));
    const float size = grid_.cellSize();
    const glm::vec2 g0 = (a - grid_.lo()) / size, g1 = (b - grid_.lo()) / size;
    glm::ivec2 at(int(std::floor(g0.x)), int(std::floor(g0.y)));
    const glm::ivec2 end(int(std::floor(g1.x)), int(std::floor(g1.y)));
    const glm::vec2 d = g1 - g0;
    const glm::ivec2 step(d.x > 0 ? 1 : -1, d.y > 0 ? 1 : -1);
    auto firstCross = [](float p, float dp) {
      if (dp == 0.0f) return std::numeric_limits<float>::infinity();
      const float edge = dp > 0 ? std::floor(p) + 1.0f : std::floor(p);
      return (edge - p) / dp;
    };
    glm::vec2 tMax(firstCross(g0.x, d.x), firstCross(g0.y, d.y));
    const glm::vec2 tDelta(
        d.x != 0.0f ? std::abs(1.0f / d.x) : std::numeric_limits<float>::infinity(),
        d.y != 0.0f ? std::abs(1.0f / d.y) : std::numeric_limits<float>::infinity());
    const size_t limit = size_t(std::abs(end.x - at.x) + std::abs(end.y - at.y)) + 2;
    for (size_t k = 0; k < limit; ++k) {
      // Cells outside the grid clamp to its border (xz_grid.h).
      collect(glm::clamp(at, glm::ivec2(0), dims - 1));
      if (at == end) break;
      // Step both ways at a corner, so no cell the segment touches is skipped.
      if (tMax.x < tMax.y) {
        at.x += step.x;
        tMax.x += tDelta.x;
      } else if (tMax.y < tMax.x) {
        at.y += step.y;
        tMax.y += tDelta.y;
      } else {
        collect(glm::clamp(glm::ivec2(at.x + step.x, at.y), glm::ivec2(0), dims - 1));
        at += step;
        tMax += tDelta;
      }
    }
  }
  for (uint32_t index : candidates) {
    const Plane& pl = planes_[index];
    if (!pl.bounds.overlaps(shaft)) continue;
    bool behind = true;
    for (const glm::dvec3& p : vertices) behind &= glm::dot(pl.n, p) < pl.bottom - pl.margin;
    if (!behind) continue;
    // The footprint F (planar_fusion.h): its points, each tested as it
    // comes. Every point of F lies in some piece, or F is not covered
    // (most planes fail on the first points); if all lie in one (convex)
    // piece, so does F.
    const double slack = 4.0 * pl.margin;
    points.clear();
    size_t home = 0;
    bool inOne = true, inAll = true;
    auto take = [&](const glm::dvec3& x) {
      const glm::dvec2 q(glm::dot(x, pl.u), glm::dot(x, pl.v));
      points.push_back(q);
      // A point counts as in a piece when it lies in the piece grown by
      // `slack` and in its bounds grown by as much (a sharp corner's grown
      // tip reaches farther: the pieces' grid holds only the bounds).
      auto inBounds = [&](const glm::dvec4& b) {
        return b.x <= q.x + slack && b.z >= q.x - slack && b.y <= q.y + slack && b.w >= q.y - slack;
      };
      if (inBounds(pl.pieceBounds[home]) && insidePiece(pl.pieces[home], q, slack)) return true;
      inOne = false;
      // Pieces whose u range can hold q: lowest u in [q.u - widest - slack, q.u + slack].
      const double from = q.x - pl.widest - slack;
      size_t k = size_t(std::partition_point(pl.pieceBounds.begin(), pl.pieceBounds.end(),
                                             [&](const glm::dvec4& b) { return b.x < from; }) -
                        pl.pieceBounds.begin());
      for (; k < pl.pieces.size() && pl.pieceBounds[k].x <= q.x + slack; ++k) {
        if (!inBounds(pl.pieceBounds[k])) continue;
        if (insidePiece(pl.pieces[k], q, slack)) {
          home = k;
          return true;
        }
      }
      return false;
    };
    // The line from the cell's centre to the face's first vertex first.
    {
      const glm::dvec3 c(cell.center()), p = vertices[0];
      const double hc = glm::dot(pl.n, c), hp = glm::dot(pl.n, p);
      inAll = take(c + (p - c) * ((hc - pl.top) / (hc - hp)));
      points.clear();
      inOne = true;  // `home` holds the centre line's piece
    }
    for (size_t ci = 0; ci < 8 && inAll; ++ci) {
      const glm::dvec3& c = corners[ci];
      const double hc = glm::dot(pl.n, c);
      for (size_t vi = 0; vi < vertices.size() && inAll; ++vi) {
        const glm::dvec3& p = vertices[vi];
        const double hp = glm::dot(pl.n, p);
        inAll = take(c + (p - c) * ((hc - pl.top) / (hc - hp))) &&
                take(c + (p - c) * ((hc - pl.bottom) / (hc - hp)));
      }
    }
    if (!inAll) continue;
    if (inOne) return true;
    std::vector<glm::dvec2> footprint = convexHull2d(points);
    if (footprint.size() < 3) continue;
    // F minus each Q_i (planar_fusion.h, numerics).
    if (coveredBy(footprint, pl.pieces, pl.pieceBounds, slack)) return true;
  }
  return false;
}

}  // namespace vistream
