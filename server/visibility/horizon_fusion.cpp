// Occluder fusion by 2.5D occlusion horizons: Wonka, Wimmer and Schmalstieg,
// "Visibility Preprocessing with Occluder Fusion for Urban Walkthroughs"
// (EGWR 2000), section 4 (occluder shrinking: a point hidden from a sample by
// occluders shrunk by epsilon is hidden from every viewpoint within epsilon
// of the sample by the original ones) and section 5 (2.5D occluders, samples
// on the cell); the occlusion of each sample is kept as an occlusion horizon
// over azimuth (Downs, Moeller and Sequin, "Occlusion Horizons for Driving
// through Urban Scenery", I3D 2001, section 3) instead of a cull map.
//
// Notation: horizontal means the X/Z plane; for a point p, p_h is (p.x, p.z).
//
// 1. Solid columns. A column is a grid square S times a height interval
//    [b, t]. The interval is a gap between the padded height ranges of the
//    triangles that meet S grown by a margin (for each, a range holding the
//    heights of its part over the grown square: its plane's heights at the
//    square's corners, cut to the triangle's own heights; grown by the
//    margin), leaving out exactly vertical triangles
//    (collinear in X/Z). So only vertical triangles meet the closed box
//    S x [b, t]; their lines cut S into convex pieces. At the centroid of
//    each piece with area, at mid-gap height (or, when that is not above
//    the floor f of the enclosure found, midway between f and t), one
//    enclosure K of common/world/solids.h has odd crossing parity along
//    three generic upward rays. K, its dangling sheets peeled, is a cycle
//    modulo 2 (its edge pieces each used an even number of times, whatever
//    its winding or manifoldness), or one once closed by vertical curtains
//    down from its open base pieces, which all lie at or below its floor f,
//    and a cap far below. Call that cycle K'. Parity of a cycle does not
//    depend on the ray, and an upward ray from above f meets no curtain, so
//    the test reads K' (three rays guard against a ray through an edge).
//    Only the part of the gap above f (by the margin) is kept: the column
//    is [max(b, f + margin), t]. Solids welds corners and cuts T-junctions
//    within its tolerance (1 cm), so the proof holds for the surface with
//    cracks narrower than that closed: such a crack is taken as blocking.
//    A piece's slice of the box meets no triangle, and every point of the
//    piece's prism is joined to that slice by a vertical segment meeting no
//    triangle, unless it lies on a vertical triangle; so every point of the
//    box is inside some such K or on a triangle. Pieces without area hold
//    only points of the lines: on a vertical triangle, or limits of inside
//    points that are on no triangle, hence inside. A piece thinner than a
//    tenth of the margin leaves the column out (float rounding could carry
//    its test point across a wall). A column that no vertical triangle cuts
//    takes the answer of its uncut left neighbour for a gap overlapping one
//    of the neighbour's above that answer's floor by more than the margin:
//    up one column, across their shared side within the overlap (a triangle
//    meeting that side is in both columns' spans) and down the other, the
//    two test points are joined by a path above the floor meeting no
//    triangle, so they lie inside the same components.
//
// 2. Jordan. Let v be a point above K's floor f outside K' (even parity)
//    and q a point of K's interior above f (every column point is). The
//    parity of K' along the segment v-q changes, so the segment crosses K'
//    strictly between v and q; it stays above f, where K' has no curtain,
//    so it crosses a triangle of K. Hence: if the line of
//    sight from v to a point p passes strictly before p through a point q of
//    a column, either q is on a triangle or the line crosses one before q;
//    either way p is not the first surface point on it, so p is not seen
//    from v. A face is hidden from v if each of its points is.
//    Every viewpoint of the cell is above f when the cell's bottom lies
//    above f (by the margin); enclosures failing this (a cell reaching down
//    to an open base) are excluded: their columns block nothing for this
//    cell. Every served viewpoint is outside K' and off its triangles: the
//    PVS contract serves no viewpoint inside an enclosure or on its surface
//    (Solids::unservedViewpoint; issue 13, item 4), so a cell that cuts
//    into a building still has that building's columns block for its
//    viewpoints outside it.
//
// 3. Shrinking. The shrunk column field keeps, for each grid square c, the
//    lowest top and the highest base over every column whose square meets c
//    grown by r = epsilon + binMargin (a square window of ceil(r / grid)
//    columns), and no column at all if one of those is missing (not solid,
//    or outside the grid, or of an excluded solid: per cell, every shrunk
//    column within the window of an excluded solid's bounds is dropped). So for any horizontal
//    point x within r of c there is a column of a non-excluded solid over
//    x_h whose box contains heights [base(c), top(c)].
//
// 4. Viewpoints. Let v be a viewpoint of the cell, v' the point of the
//    cell's top face above it (v'_h = v_h, v'.y = Y, the top), and s the
//    sample whose rectangle holds v' (samples are the centres of a grid of
//    rectangles on the top face whose half-diagonal is at most epsilon), so
//    |v'_h - s_h| <= epsilon and v'.y = s.y. Take a face point p at
//    horizontal distance R from s, direction phi, and the line of sight
//    from v. At the fraction lam of the way from v to p its horizontal
//    position is  (1 - lam) v_h + lam p_h = [s_h + lam (p_h - s_h)] +
//    (1 - lam)(v_h - s_h), within epsilon of the point at horizontal
//    distance d = lam R along phi from s; its height is
//    (1 - lam) v.y + lam p.y, which is at most (1 - lam) Y + lam p.y and at
//    least (1 - lam) L + lam p.y, L being the cell's bottom.
//
// 5. Bins. Azimuth is cut into bins of width w = 2 pi / azimuthBins; bin k
//    is traced along its central ray only. A direction phi of the bin and
//    the central ray are at most w / 2 apart, so their points at horizontal
//    distance d are at most d w / 2 <= binMargin apart for d up to the
//    reach 2 binMargin / w. If the central ray at distance d lies in the
//    square c, the line of sight of step 4 lies, at lam = d / R, within
//    epsilon + binMargin = r of c, over a column with [base(c), top(c)].
//    It lies inside that column when
//       (a) (1 - lam) Y + lam p.y <= top(c), i.e. (p.y - Y) / R <= (top(c) - Y) / d
//           (the elevation slope of p is below the column's, seen from s), and
//       (b) (1 - lam) L + lam p.y >= base(c), which holds when L >= base(c)
//           and either p.y >= base(c) or d (a + base(c) - p.y) <= R a with
//           a = L - base(c) > 0,
//    and lam < 1, i.e. d < R (the column point lies strictly before p).
//    So each traced square yields a step of the horizon: (d, slope, base)
//    meaning "beyond horizontal distance d, every point whose slope is at
//    most `slope` and that meets (b) is hidden from every viewpoint that
//    maps to this sample". For a square the central ray crosses over
//    [t_in, t_out], d = t_in when top(c) > Y (the steeper bound), else
//    d = min(t_out, reach) (any d in [t_in, t_out] is allowed).
//
// 6. Faces. A face is a union of triangles. From s, all its points lie in
//    the azimuth wedge of its vertices (when that wedge is narrower than pi,
//    else the face is kept), at horizontal distance at least R_min (the
//    distance from s_h to its projected triangles' edges; s_h is outside
//    them because the wedge is narrower than pi) and at most R_max (the
//    farthest vertex), so its slope is at most (maxY - Y) / R_min when
//    maxY > Y and (maxY - Y) / R_max otherwise, and p.y >= minY. The face
//    is hidden from s when every bin of its wedge has a step with
//    d < R_min, slope strictly above the face's, and (b) for minY and R_min
//    (the bound is monotone in R and p.y); a bin that fails this is tried
//    again with the same bounds of the part of the face inside the bin's
//    wedge (its triangles clipped to the wedge grown by 1e-9 rad), which is
//    all that bin must hide. Hidden from every sample means
//    hidden from every viewpoint of the cell (step 4 maps each viewpoint to
//    a sample), which is what is culled.
//
// 7. Walls (HorizonFusionOptions::walls). A wall line (wall_occluders.h) is
//    a vertical plane, in X/Z the line n . x = c (n a horizontal unit
//    normal, t its tangent, u = t . x), with heights [B(u), T(u)] that its
//    triangles cover at every u of each of its bins. With tau the larger of
//    the weld tolerance of step 1 (1 cm) and the margin, its triangles lie
//    within tau / 4 of the plane and the cover joins them across gaps of at
//    most tau / 4 along the plane, so every crack it closes is narrower
//    than tau (at most tau / 2 across the plane, tau / 4 along it); such
//    cracks are taken as closed, as the welding of step 1 does, and the
//    argument below is for the wall so read. Let bin k's central
//    ray from s cross the line at distance d0 (in a column the walk reads)
//    at an angle whose sine is sigma = |n . dir| >= 0.1, and let
//    delta = (r + 2 tau) / sigma with r = epsilon + binMargin. Take the line
//    of sight of step 4 from v to a point p of the bin at distance R, and
//    write its horizontal position at fraction lam as c(lam) + e(lam), c the
//    central ray's point at distance lam R; by steps 4 and 5, |e| <= r
//    wherever lam R <= reach. Its signed distance to the line,
//    f(lam) = (lam R - d0) sigma + n . e(lam) (the sign taken so that the
//    central ray goes from negative to positive), is <= 0 at lam R = d0 - delta
//    and >= 0 at lam R = d0 + delta when d0 - delta > 0 and
//    d0 + delta <= reach; f is affine in lam, so the line of sight meets the
//    plane at some lam1 with lam1 R in [d0 - delta, d0 + delta]. There its
//    offset along the line from the central crossing x0 is
//    (lam1 R - d0) cos + t . e with (lam1 R - d0) sigma = -n . e, at most
//    |e| / sigma <= delta. So the crossing lies over the window
//    [u0 - delta, u0 + delta] of the line, u0 = t . x0, where the wall covers
//    [B, T] = [max B(u), min T(u)] over the window's bins. Its height is
//    (1 - lam1) v.y + lam1 p.y: at most T when (p.y - Y) / R <= (T - Y) / d
//    for every d in [d0 - delta, d0 + delta], the hardest being
//    d = d0 + delta when T > Y and d = d0 - delta otherwise; at least B by
//    (b) of step 5 with d = d0 + delta (the bound grows with d) and L >= B.
//    And lam1 < 1 when R > d0 + delta. So the wall gives the step
//    (d0 + delta, (T - Y) / (d0 +- delta), B): the line of sight meets a
//    triangle strictly before p, and p is not seen from v (as in step 2, a
//    point on a triangle blocks). A wall's step lies beyond the column it is
//    found in: it waits (Walk::pending) until the walk has entered every
//    column before its distance, so that the horizon's steps keep rising;
//    taken after a column step that ends farther, it takes that distance
//    (a step moved farther hides a subset: what lies beyond the new
//    distance lies beyond the old), so distances never fall either.
//    Block bounds take the walls' tops: a wall step's slope is at most
//    (T - Y) / tin when T > Y and (T - Y) / exit otherwise, as a column's.
//
// 8. Chains of walls (HorizonFusionOptions::wallChains). Where the window
//    of step 7 runs off the end of the covered run of the wall line the
//    central ray crosses (a building's corner), the wall may go on in
//    another line joined to it there (wall_occluders.h: the run's end, a
//    corner of one of its triangles projected on its plane, within tau / 8
//    of the other's plane and of one of its runs). Between the triangles
//    of the two lines the crack is then narrower than tau: at most tau / 4
//    from the corner to its projection, tau / 8 across and along to the
//    other line's run (sqrt(2) tau / 8), and tau / 4 across plus tau / 4
//    along from there to that line's triangles, 0.93 tau in all; it is
//    closed, as in step 7. Put strip
//    coordinates on the plane, a = dir . (x - s_h) along the central ray
//    and b = perp . (x - s_h) across it, and let rp = r + 2 tau. From the
//    crossing, follow the line both ways, turning at joints, until each
//    way reaches the side |b| = rp of the strip; the ways must reach
//    opposite sides, every piece followed must be covered by its line
//    (heights [B, T] = the highest base and lowest top over all pieces,
//    B below the cell), and the pieces' a lie in [amin, amax]. The chain
//    so followed is a connected curve in the rectangle [amin, amax] x
//    [-rp, rp] joining its sides b = -rp and b = rp. The line of sight of step 4 lies
//    within r of the central ray's point at distance lam R (steps 4-5), so
//    |b| <= r and |a - lam R| <= r: at lam R <= amin - rp it has a < amin,
//    at lam R >= amax + rp it has a > amax (both within the reach), and in
//    between it holds a path across the rectangle from its side a = amin
//    to its side a = amax. Two such paths in a rectangle meet, so the line
//    of sight crosses the chain at some lam1 with lam1 R in
//    [amin - rp, amax + rp], over a covered piece. As in step 7 (with
//    d0 - delta and d0 + delta now amin - rp > 0 and amax + rp <= reach) the
//    chain gives the step (amax + rp, (T - Y) / (amax + rp or amin - rp), B).
//    It is found in the column where the central ray crosses the first
//    line, which is before amax + rp, with T at most that line's top: the
//    block bounds of step 7 hold for it.
//
// Cost: the horizon of a sample is traced lazily, bin by bin, only where a
// face still needs it, and each bin only as far as the faces asking need
// (their R_min), stopping at the first step that hides the face; a later
// face resumes the walk where it stopped. A bin skips regions whose
// highest top cannot raise it (skipping changes no step, except for the
// last bits of a distance recomputed after a jump, far below the margin of
// step 1): first super-blocks of 64 x 64 columns, then blocks of 8 x 8
// within the rest, where an empty block passes at once every block nearer
// than the nearest one with a top (on city2 all but 0.3% of the skipped
// blocks were empty, one at a time), and stops once no column of the scene
// can raise it, or at the reach.
// A bin remembers the distance of the step that last hid a face in it; at
// the next sample it first reads only the columns from 4 m before to 2 m
// after that distance (a piece of walk: step 5 holds for every column the
// central ray crosses, wherever the reading starts), and walks from the
// sample only for a face that piece does not hide (city2 4 m cells: 11.6 k
// bins walked a cell -> 4.3 k, columns read 228 k -> 158 k).
// Faces seen from one sample are not tested from the next.
#include "server/visibility/horizon_fusion.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <tuple>

#include "common/core/check.h"
#include "common/core/timer.h"
#include "common/raycast/ray_query.h"
#include "common/spatial/convex_polygon.h"
#include "common/spatial/distance_transform.h"
#include "common/world/solids.h"
#include "server/visibility/wall_occluders.h"

namespace vistream {
namespace {

constexpr float kNoTop = -std::numeric_limits<float>::infinity();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Steep, generic upward directions for the parity votes (no axis, no
// diagonal of an axis-aligned box, no rational slope a city would use).
// Steeper and fewer than solidTestDirections(): the height field asks
// once per column gap, a steep ray leaves the city after few hits, and a
// column counts as inside only by a unanimous vote.
const std::array<glm::vec3, 3>& parityDirections() {
  static const std::array<glm::vec3, 3> d{glm::normalize(glm::vec3(0.1234f, 1.0f, 0.0719f)),
                                          glm::normalize(glm::vec3(-0.0871f, 1.0f, 0.1537f)),
                                          glm::normalize(glm::vec3(0.1621f, 1.0f, -0.1113f))};
  return d;
}

// Keeps the part of the convex polygon where coordinate `axis` is >= v
// (above) or <= v (below).
void clipAxis(std::vector<glm::dvec3>& poly, std::vector<glm::dvec3>& out, int axis, double v,
              bool above) {
  out.clear();
  const size_t n = poly.size();
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec3& a = poly[i];
    const glm::dvec3& b = poly[(i + 1) % n];
    const double da = above ? a[axis] - v : v - a[axis];
    const double db = above ? b[axis] - v : v - b[axis];
    if (da >= 0.0) out.push_back(a);
    if ((da >= 0.0) != (db >= 0.0)) {
      const double f = da / (da - db);
      glm::dvec3 x = a + f * (b - a);
      x[axis] = v;
      out.push_back(x);
    }
  }
  poly.swap(out);
}

double pointSegmentDistance(glm::dvec2 p, glm::dvec2 a, glm::dvec2 b) {
  const glm::dvec2 ab = b - a;
  const double len2 = glm::dot(ab, ab);
  const double f = len2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / len2, 0.0, 1.0) : 0.0;
  return glm::length(p - (a + f * ab));
}

// One step of an occlusion horizon (proof, step 5).
struct Step {
  double d;      // horizontal distance from the sample
  double slope;  // (height - sample height) / distance
  double base;   // highest base of the columns behind it
};

struct IRect {
  int i0, j0, i1, j1;  // inclusive grid index ranges
};

}  // namespace

struct HorizonFusion::Impl {
  const Scene& scene;
  std::unique_ptr<const StaticWorld> owned;  // when the caller gave none
  // The static world's (owned or the caller's).
  const FlatTriangles& tris;
  const RayQuery& rays;
  const Solids& solids;
  // Solids here are the enclosures of Solids (welded parity groups that are
  // cycles modulo 2, or once capped below their floor; either winding):
  // "component" below means such a solid.
  std::vector<uint8_t> hasColumns;            // per enclosure: some column lies inside it
  std::vector<uint32_t> faceStart, faceTris;  // static triangles by face ID
  // The grid and its shrunk columns (proof, step 3).
  glm::dvec2 lo{0.0};
  double g = 1.0;
  int nx = 0, nz = 0;
  int window = 0;  // shrinking radius in columns
  // Shrunk top and base per column, stored block by block (kBlock x kBlock
  // columns together) so that a horizon walking a block reads few cache
  // lines; top == kNoTop: nothing occludes there. With them, the column's
  // first entry in wallLineIds (its last is the next column's first): one
  // read gives a walk all it needs of a column. One more column at the end
  // closes the last range.
  struct Column {
    float top = kNoTop;
    float base = 0.0f;
    uint32_t firstWall = 0;
  };
  std::vector<Column> columns;
  size_t columnIndex(int i, int j) const {
    return (size_t(j / kBlock) * size_t(bx) + size_t(i / kBlock)) * size_t(kBlock * kBlock) +
           size_t((j % kBlock) * kBlock + i % kBlock);
  }
  double maxTop = -kInf;
  // The highest shrunk top per block of kBlock x kBlock columns (kNoTop:
  // nothing occludes there), so that a horizon skips whole blocks.
  static constexpr int kBlock = 8;
  int bx = 0, bz = 0;
  std::vector<float> blockTop;
  // The same per super-block of kSuper x kSuper blocks: a horizon crossing
  // a street grid or open land passes most of its blocks by these.
  static constexpr int kSuper = 8;
  int sx = 0, sz = 0;
  std::vector<float> superTop;
  // Per block, the Chebyshev distance in blocks to the nearest block with
  // a top (at most 255): a horizon in an empty block passes every block
  // closer than that at once (open ground and streets, where the blocks are
  // empty and each super-block still holds a building).
  std::vector<uint8_t> emptyReach;
  size_t solidColumns = 0;
  double margin = 1e-3;  // metres, for clipping and heights
  // Per level of bins (HorizonFusion::kRefine times finer each), bin k's
  // central direction (cos, sin of its azimuth) and the half-spaces
  // (x, z normals) bounding its wedge, each side widened by 1e-9 rad: the
  // same for every sample and cell, so a cull computes no sines.
  struct BinTable {
    double binWidth = 0.0;
    std::vector<glm::dvec2> centre;
    std::vector<glm::dvec3> lowSide, highSide;
  };
  std::vector<BinTable> binTables;
  // Vertical walls (proof, step 7) and, per column (in columnIndex order,
  // from Column::firstWall), the wall lines whose triangles meet its square
  // grown by the margin.
  WallOccluders walls;
  std::vector<uint32_t> wallLineIds;
  double shrinkRadius = 0.0;  // epsilon + binMargin
  bool wallChains = true;     // HorizonFusionOptions::wallChains
  // Smallest sine of the angle between a horizon's ray and a wall it
  // crosses: grazier walls are eroded by more than 10 times the radius.
  static constexpr double kMinWallSine = 0.1;
  // Metres: wall triangles within this of their line, cracks between them
  // narrower than it taken as closed (proof, step 7).
  double wallTolerance() const { return std::max(margin, solids.weldTolerance()); }

  Impl(const Scene& s, std::unique_ptr<const StaticWorld> own, const StaticWorld& world)
      : scene(s),
        owned(std::move(own)),
        tris(*world.triangles),
        rays(*world.rays),
        solids(world.solids) {}

  // The enclosure whose interior holds p by all three votes
  // (Solids::oddEnclosures), or kNoHit.
  uint32_t enclosureHolding(const glm::vec3& p) const {
    std::vector<uint32_t> first, other, both;
    const auto& dirs = parityDirections();
    const float far = std::numeric_limits<float>::infinity();
    if (!solids.oddEnclosures(rays, Ray{p, dirs[0], 0.0f, far}, first) || first.empty())
      return kNoHit;
    for (size_t d = 1; d < dirs.size(); ++d) {
      if (!solids.oddEnclosures(rays, Ray{p, dirs[d], 0.0f, far}, other)) return kNoHit;
      both.clear();
      std::set_intersection(first.begin(), first.end(), other.begin(), other.end(),
                            std::back_inserter(both));
      first.swap(both);
      if (first.empty()) return kNoHit;
    }
    return first.front();
  }

  // The floor of an enclosure (-infinity for a sealed one or for kNoHit):
  // parity by upward rays tells inside from outside only above it.
  double floorOf(uint32_t e) const {
    return e == kNoHit ? -kInf : double(solids.enclosureFloor(e));
  }

  // The enclosure holding the points of the gap [a, b] over (x, z) that
  // lie above its floor, tested at mid-gap, or again midway between the
  // floor and b when mid-gap is not above it; kNoHit if none.
  uint32_t insideAbove(double x, double z, double a, double b) const {
    const uint32_t e = enclosureHolding(glm::vec3(float(x), float(0.5 * (a + b)), float(z)));
    if (e == kNoHit) return e;
    const double floor = floorOf(e) + margin;
    if (floor < 0.5 * (a + b) - margin) return e;
    if (b - floor <= 4.0 * margin) return kNoHit;
    const double y = 0.5 * (floor + b);
    return enclosureHolding(glm::vec3(float(x), float(y), float(z))) == e ? e : kNoHit;
  }

  void build(const HorizonFusionOptions& o);
  void buildWalls();
  // Calls f(i, j) for every column whose square, grown by `grow`, meets the
  // segment a-b (X/Z); some columns near it twice at most per row, never
  // one it meets left out.
  template <class F>
  void forEachColumnOfSegment(glm::dvec2 a, glm::dvec2 b, double grow, F&& f) const {
    const int j0 = std::max(0, int(std::floor((std::min(a.y, b.y) - grow - lo.y) / g)));
    const int j1 = std::min(nz - 1, int(std::floor((std::max(a.y, b.y) + grow - lo.y) / g)));
    for (int j = j0; j <= j1; ++j) {
      const double za = lo.y + j * g - grow, zb = za + g + 2.0 * grow;
      double s0 = 0.0, s1 = 1.0;
      if (b.y != a.y) {
        double sa = (za - a.y) / (b.y - a.y), sb = (zb - a.y) / (b.y - a.y);
        if (sa > sb) std::swap(sa, sb);
        s0 = std::max(s0, sa);
        s1 = std::min(s1, sb);
      } else if (a.y < za || a.y > zb) {
        continue;
      }
      if (s0 > s1) continue;
      double xa = a.x + s0 * (b.x - a.x), xb = a.x + s1 * (b.x - a.x);
      if (xa > xb) std::swap(xa, xb);
      const int i0 = std::max(0, int(std::floor((xa - grow - lo.x) / g)));
      const int i1 = std::min(nx - 1, int(std::floor((xb + grow - lo.x) / g)));
      for (int i = i0; i <= i1; ++i) f(i, j);
    }
  }
  IRect rectOf(const Box3f& b, int grow) const {
    auto ix = [&](double x) { return int(std::floor((x - lo.x) / g)); };
    auto iz = [&](double z) { return int(std::floor((z - lo.y) / g)); };
    return {ix(b.lo.x) - grow, iz(b.lo.z) - grow, ix(b.hi.x) + grow, iz(b.hi.z) + grow};
  }
};

void HorizonFusion::Impl::build(const HorizonFusionOptions& o) {
  size_t nbins = size_t(o.azimuthBins);
  for (int l = 0; l <= o.refinements; ++l, nbins *= size_t(HorizonFusion::kRefine)) {
    BinTable& t = binTables.emplace_back();
    t.binWidth = 2.0 * std::numbers::pi / double(nbins);
    for (size_t k = 0; k < nbins; ++k) {
      const double phi = (double(k) + 0.5) * t.binWidth;
      const double p0 = double(k) * t.binWidth - 1e-9, p1 = double(k + 1) * t.binWidth + 1e-9;
      t.centre.emplace_back(std::cos(phi), std::sin(phi));
      // The wedge between azimuths p0 and p1 (x = cos, z = sin).
      t.lowSide.emplace_back(std::sin(p0), 0.0, -std::cos(p0));
      t.highSide.emplace_back(-std::sin(p1), 0.0, std::cos(p1));
    }
  }
  const size_t nc = solids.enclosureCount();
  hasColumns.assign(nc, 0);
  // Triangles by face (counting sort).
  faceStart.assign(size_t(scene.faceCount) + 1, 0);
  Box3f bounds;
  for (size_t t = 0; t < tris.size(); ++t) {
    if (tris.faceIds[t] < scene.faceCount) ++faceStart[tris.faceIds[t] + 1];
    if (!tris.degenerate[t]) bounds.extend(tris.triangleBounds(t));
  }
  for (size_t f = 0; f < scene.faceCount; ++f) faceStart[f + 1] += faceStart[f];
  faceTris.resize(faceStart.back());
  {
    std::vector<uint32_t> fn(faceStart.begin(), faceStart.end() - 1);
    for (size_t t = 0; t < tris.size(); ++t) {
      if (tris.faceIds[t] < scene.faceCount) faceTris[fn[tris.faceIds[t]]++] = uint32_t(t);
    }
  }
  if (bounds.empty()) return;
  const glm::dvec3 blo(bounds.lo), bhi(bounds.hi);
  // Margin: far above float rounding of the coordinates (CONTRIBUTING,
  // "Conservative geometry" uses 1e-7 of the magnitude; a millimetre here
  // costs nothing at city scale).
  margin = 1e-3 + 1e-6 * std::max({std::abs(blo.x), std::abs(blo.y), std::abs(blo.z),
                                   std::abs(bhi.x), std::abs(bhi.y), std::abs(bhi.z)});
  const double area = (bhi.x - blo.x + 2.0) * (bhi.z - blo.z + 2.0);
  g = std::max(o.gridSize, std::sqrt(area / double(kMaxColumns)));
  lo = glm::dvec2(blo.x - 1.0, blo.z - 1.0);
  nx = int(std::ceil((bhi.x + 1.0 - lo.x) / g));
  nz = int(std::ceil((bhi.z + 1.0 - lo.y) / g));

  // Raw columns, row by row (proof, step 1).
  std::vector<std::vector<uint32_t>> rowTris(static_cast<size_t>(nz));
  for (size_t t = 0; t < tris.size(); ++t) {
    if (tris.degenerate[t]) continue;
    const Box3f b = tris.triangleBounds(t);
    const int j0 = std::max(0, int(std::floor((b.lo.z - margin - lo.y) / g)));
    const int j1 = std::min(nz - 1, int(std::floor((b.hi.z + margin - lo.y) / g)));
    for (int j = j0; j <= j1; ++j) rowTris[size_t(j)].push_back(uint32_t(t));
  }
  // Exactly vertical triangles (collinear X/Z projection, tested in double
  // on float inputs) do not bound a column's height: they cut its square
  // into pieces, each tested on its own (proof, step 1).
  std::vector<uint8_t> vertical(tris.size(), 0);
  for (size_t t = 0; t < tris.size(); ++t) {
    const glm::dvec3 a(tris.vertex(t, 0)), b(tris.vertex(t, 1)), c(tris.vertex(t, 2));
    vertical[t] = (b.x - a.x) * (c.z - a.z) - (b.z - a.z) * (c.x - a.x) == 0.0;
  }
  std::vector<float> rawTop(size_t(nx) * size_t(nz), kNoTop), rawBase(rawTop.size(), 0.0f);
  std::vector<uint8_t> rawSolid(rawTop.size(), 0);
  std::vector<std::vector<uint32_t>> rowComps(static_cast<size_t>(nz));
  tbb::parallel_for(0, nz, [&](int j) {
    // Per thread, emptied for each row (their capacity is kept).
    thread_local std::vector<std::vector<std::pair<double, double>>> spans;
    thread_local std::vector<std::vector<uint32_t>> cuts;
    spans.resize(size_t(nx));
    cuts.resize(size_t(nx));
    for (auto& v : spans) v.clear();
    for (auto& v : cuts) v.clear();
    std::vector<glm::dvec3> poly, tmp;
    const double z0 = lo.y + j * g, z1 = z0 + g;
    for (uint32_t t : rowTris[size_t(j)]) {
      const Box3f b = tris.triangleBounds(t);
      const int i0 = std::max(0, int(std::floor((b.lo.x - margin - lo.x) / g)));
      const int i1 = std::min(nx - 1, int(std::floor((b.hi.x + margin - lo.x) / g)));
      // Heights over a square come from the triangle's plane, without
      // clipping (a ground tile covers thousands of squares).
      const glm::dvec3 ta(tris.vertex(t, 0)), tb(tris.vertex(t, 1)), tc(tris.vertex(t, 2));
      const double area2 = (tb.x - ta.x) * (tc.z - ta.z) - (tb.z - ta.z) * (tc.x - ta.x);
      const glm::dvec3 tn = glm::cross(tb - ta, tc - ta);
      auto planeY = [&](double x, double z) {
        return ta.y - (tn.x * (x - ta.x) + tn.z * (z - ta.z)) / tn.y;
      };
      // A vertical triangle's projection is the segment between its two
      // farthest-apart projected corners; it meets a square exactly when
      // that segment does (Liang and Barsky's clipping of the segment).
      glm::dvec2 sa(ta.x, ta.z), sb(tb.x, tb.z);
      if (vertical[t]) std::tie(sa, sb) = farthestXzCorners(tris, t);
      auto segmentMeetsSquare = [&](double xa, double xb, double za, double zb) {
        double u0 = 0.0, u1 = 1.0;
        const glm::dvec2 d = sb - sa;
        const double lim[4][2] = {
            {-d.x, sa.x - xa}, {d.x, xb - sa.x}, {-d.y, sa.y - za}, {d.y, zb - sa.y}};
        for (const auto& [pq, q] : lim) {
          if (pq == 0.0) {
            if (q < 0.0) return false;
            continue;
          }
          const double u = q / pq;
          if (pq < 0.0)
            u0 = std::max(u0, u);
          else
            u1 = std::min(u1, u);
          if (u0 > u1) return false;
        }
        return true;
      };
      for (int i = i0; i <= i1; ++i) {
        const double x0 = lo.x + i * g, x1 = x0 + g;
        if (vertical[t]) {
          if (segmentMeetsSquare(x0 - margin, x1 + margin, z0 - margin, z1 + margin))
            cuts[size_t(i)].push_back(t);
          continue;
        }
        // Not vertical: the part of the triangle over the grown square has
        // heights within the plane's over the square's corners and within
        // the triangle's own; a square all of whose corners lie outside one
        // edge does not meet it (the rows and columns outside its bounds
        // were never visited). A wider span only narrows the gaps.
        const double cx[2] = {x0 - margin, x1 + margin}, cz[2] = {z0 - margin, z1 + margin};
        int outside[3] = {0, 0, 0};
        double y0 = kInf, y1 = -kInf;
        for (int k = 0; k < 4; ++k) {
          const double x = cx[k & 1], z = cz[k >> 1];
          const double e[3] = {(tb.x - ta.x) * (z - ta.z) - (tb.z - ta.z) * (x - ta.x),
                               (tc.x - tb.x) * (z - tb.z) - (tc.z - tb.z) * (x - tb.x),
                               (ta.x - tc.x) * (z - tc.z) - (ta.z - tc.z) * (x - tc.x)};
          for (int m = 0; m < 3; ++m) outside[m] += area2 > 0.0 ? e[m] < 0.0 : e[m] > 0.0;
          const double y = planeY(x, z);
          y0 = std::min(y0, y);
          y1 = std::max(y1, y);
        }
        if (outside[0] == 4 || outside[1] == 4 || outside[2] == 4) continue;
        if (outside[0] + outside[1] + outside[2] > 0) {
          // Float rounding of the plane's heights is far below the margin.
          y0 = std::max(y0, double(b.lo.y));
          y1 = std::min(y1, double(b.hi.y));
        }
        spans[size_t(i)].push_back({y0 - margin, y1 + margin});
      }
    }
    std::vector<std::pair<double, double>> gaps;
    std::vector<glm::dvec3> lines;  // (n.x, n.z, c): n . (x, z) = c
    std::vector<std::vector<glm::dvec3>> pieces, next;
    std::vector<uint32_t> comps;
    // The gaps tested in the column to the left, when no vertical triangle
    // cuts it, and their answers. Two uncut neighbours whose gaps overlap by
    // more than the margin are joined by a path that meets no triangle (up
    // the one column, across their shared side inside the overlap, down the
    // other; triangles meeting that side are in both columns' spans), so a
    // point of the one is inside the same solids as a point of the other.
    struct Tested {
      double a, b;
      uint32_t inside;
    };
    std::vector<Tested> left, here;
    int leftColumn = -2;
    for (int i = 0; i < nx; ++i) {
      auto& s = spans[size_t(i)];
      if (s.size() < 2) continue;
      std::sort(s.begin(), s.end());
      gaps.clear();
      double reach = s[0].second;
      for (size_t k = 1; k < s.size(); ++k) {
        if (s[k].first > reach) gaps.push_back({reach, s[k].first});
        reach = std::max(reach, s[k].second);
      }
      if (gaps.empty()) continue;
      // The pieces of the square cut by the lines of the vertical triangles.
      const double x0 = lo.x + i * g, x1 = x0 + g;
      lines.clear();
      bool tooMany = false;
      for (uint32_t t : cuts[size_t(i)]) {
        const auto [a, b] = farthestXzCorners(tris, t);
        glm::dvec2 n(a.y - b.y, b.x - a.x);
        if (glm::length(n) == 0.0) continue;
        n /= glm::length(n);
        if (n.x < 0.0 || (n.x == 0.0 && n.y < 0.0)) n = -n;
        const glm::dvec3 line(n.x, n.y, glm::dot(n, a));
        bool known = false;
        for (const glm::dvec3& l : lines) known |= glm::length(l - line) < 1e-9;
        if (!known) lines.push_back(line);
        if (lines.size() > 6) tooMany = true;
      }
      if (tooMany) continue;
      pieces.assign(1, {{x0, 0.0, z0}, {x1, 0.0, z0}, {x1, 0.0, z1}, {x0, 0.0, z1}});
      for (const glm::dvec3& l : lines) {
        next.clear();
        for (const auto& piece : pieces)
          for (int side = 0; side < 2; ++side) {
            // Keep n . (x, z) >= c (side 0) or <= c (side 1); clipAxis on a
            // coordinate holding n . (x, z).
            poly.clear();
            for (const glm::dvec3& v : piece) poly.push_back({v.x, l.x * v.x + l.y * v.z, v.z});
            clipAxis(poly, tmp, 1, l.z, side == 0);
            if (poly.size() >= 3) next.push_back(poly);
          }
        pieces.swap(next);
      }
      // A piece without area holds only points of the lines, each on a
      // vertical triangle or a limit of points of the pieces beside it (the
      // interior of a solid is open and its surface is the triangles, so
      // such a point is inside when those are). A sliver thinner than float
      // rounding cannot be tested reliably: the column is left out.
      bool sliver = false;
      std::erase_if(pieces, [&](const std::vector<glm::dvec3>& piece) {
        double twiceArea = 0.0, diameter = 0.0;
        for (size_t k = 0; k < piece.size(); ++k) {
          const glm::dvec3& a = piece[k];
          const glm::dvec3& b = piece[(k + 1) % piece.size()];
          twiceArea += a.x * b.z - b.x * a.z;
          for (const glm::dvec3& c : piece)
            diameter = std::max(diameter, glm::length(glm::dvec2(c.x - a.x, c.z - a.z)));
        }
        const double pieceArea = 0.5 * std::abs(twiceArea);
        if (pieceArea <= 1e-12 * g * g) return true;
        if (pieceArea < 0.1 * margin * diameter) sliver = true;
        return false;
      });
      if (sliver) continue;
      // Tallest gap first; the first two that lie inside closed solids.
      std::sort(gaps.begin(), gaps.end(), [](const auto& a, const auto& b) {
        return a.second - a.first > b.second - b.first;
      });
      const bool uncut = lines.empty();
      here.clear();
      for (size_t k = 0; k < std::min<size_t>(gaps.size(), 2); ++k) {
        const auto [a, b] = gaps[k];
        if (b - a < margin) break;
        comps.clear();
        bool solid = !pieces.empty();
        for (const auto& piece : pieces) {
          glm::dvec3 c(0.0);
          for (const glm::dvec3& v : piece) c += v;
          c /= double(piece.size());
          uint32_t inside = kNoHit;
          bool known = false;
          if (uncut && leftColumn == i - 1)
            for (const Tested& t : left)
              if (std::min(b, t.b) - std::max({a, t.a, floorOf(t.inside)}) > margin) {
                inside = t.inside;
                known = true;
                break;
              }
          if (!known) inside = insideAbove(c.x, c.z, a, b);
          if (uncut) here.push_back({a, b, inside});
          if (inside == kNoHit) {
            solid = false;
            break;
          }
          comps.push_back(inside);
        }
        if (!solid) continue;
        // Only the part above every floor is inside (proof, step 1).
        double base = a;
        for (uint32_t e : comps) base = std::max(base, floorOf(e) + margin);
        if (b - base <= margin) continue;
        const size_t idx = size_t(j) * size_t(nx) + size_t(i);
        // Rounded inward to float.
        rawTop[idx] = std::nextafter(float(b), -std::numeric_limits<float>::infinity());
        rawBase[idx] = std::nextafter(float(base), std::numeric_limits<float>::infinity());
        rawSolid[idx] = 1;
        rowComps[size_t(j)].insert(rowComps[size_t(j)].end(), comps.begin(), comps.end());
        break;
      }
      if (uncut) {
        left.swap(here);
        leftColumn = i;
      }
    }
  });
  for (uint8_t solid : rawSolid) solidColumns += solid;
  for (const auto& row : rowComps)
    for (uint32_t c : row) hasColumns[c] = 1;

  // Shrinking (proof, step 3): separable min of tops, max of bases, over a
  // square window; outside the grid nothing occludes.
  window = int(std::ceil((o.epsilon + o.binMargin) / g));
  auto shrink = [&](std::vector<float>& t, std::vector<float>& b, bool alongX) {
    std::vector<float> t2(t.size()), b2(b.size());
    const int n = alongX ? nx : nz, m = alongX ? nz : nx;
    for (int r = 0; r < m; ++r)
      for (int q = 0; q < n; ++q) {
        float tt = std::numeric_limits<float>::infinity(), bb = -tt;
        if (q - window < 0 || q + window >= n) tt = kNoTop;
        for (int k = std::max(0, q - window); k <= std::min(n - 1, q + window) && tt != kNoTop;
             ++k) {
          const size_t idx =
              alongX ? size_t(r) * size_t(nx) + size_t(k) : size_t(k) * size_t(nx) + size_t(r);
          tt = std::min(tt, t[idx]);
          bb = std::max(bb, b[idx]);
        }
        const size_t out =
            alongX ? size_t(r) * size_t(nx) + size_t(q) : size_t(q) * size_t(nx) + size_t(r);
        t2[out] = tt;
        b2[out] = tt == kNoTop ? 0.0f : bb;
      }
    t.swap(t2);
    b.swap(b2);
  };
  shrink(rawTop, rawBase, true);
  shrink(rawTop, rawBase, false);
  bx = (nx + kBlock - 1) / kBlock;
  bz = (nz + kBlock - 1) / kBlock;
  blockTop.assign(size_t(bx) * size_t(bz), kNoTop);
  columns.assign(blockTop.size() * size_t(kBlock * kBlock) + 1, Column{});
  for (int j = 0; j < nz; ++j)
    for (int i = 0; i < nx; ++i) {
      const float t = rawTop[size_t(j) * size_t(nx) + size_t(i)];
      Column& c = columns[columnIndex(i, j)];
      c.top = t;
      c.base = rawBase[size_t(j) * size_t(nx) + size_t(i)];
      float& b = blockTop[size_t(j / kBlock) * size_t(bx) + size_t(i / kBlock)];
      b = std::max(b, t);
      if (t != kNoTop) maxTop = std::max(maxTop, double(t));
    }
  shrinkRadius = o.epsilon + o.binMargin;
  wallChains = o.wallChains;
  if (o.walls) buildWalls();
  {
    std::vector<uint8_t> hasTop(blockTop.size());
    for (size_t k = 0; k < blockTop.size(); ++k) hasTop[k] = blockTop[k] != kNoTop;
    emptyReach = chessboardDistance(hasTop, bx, bz);
  }
  sx = (bx + kSuper - 1) / kSuper;
  sz = (bz + kSuper - 1) / kSuper;
  superTop.assign(size_t(sx) * size_t(sz), kNoTop);
  for (int j = 0; j < bz; ++j)
    for (int i = 0; i < bx; ++i) {
      float& t = superTop[size_t(j / kSuper) * size_t(sx) + size_t(i / kSuper)];
      t = std::max(t, blockTop[size_t(j) * size_t(bx) + size_t(i)]);
    }
}

// Proof, step 7: the wall lines, entered in the columns their triangles
// meet; a column's block (and so its super-block) and maxTop take the
// line's highest top, so that a walk skipping a block skips no wall step.
void HorizonFusion::Impl::buildWalls() {
  // A quarter of the tolerance for the plane and for the gaps the covers
  // close, an eighth for the joints: every crack closed between members,
  // or between two joined lines, is narrower than tau (proof, steps 7-8).
  walls = WallOccluders(tris, wallTolerance() / 4.0, 0.25, wallTolerance() / 8.0);
  std::vector<std::pair<uint32_t, uint32_t>> entries;  // (column index, line)
  for (size_t k = 0; k < walls.size(); ++k)
    for (uint32_t t : walls.triangles(k)) {
      const auto [a, b] = farthestXzCorners(tris, t);
      forEachColumnOfSegment(a, b, margin + wallTolerance(), [&](int i, int j) {
        entries.push_back({uint32_t(columnIndex(i, j)), uint32_t(k)});
      });
    }
  std::sort(entries.begin(), entries.end());
  entries.erase(std::unique(entries.begin(), entries.end()), entries.end());
  for (const auto& [c, k] : entries) ++columns[c + 1].firstWall;
  for (size_t c = 0; c + 1 < columns.size(); ++c) columns[c + 1].firstWall += columns[c].firstWall;
  wallLineIds.resize(entries.size());
  for (size_t n = 0; n < entries.size(); ++n) wallLineIds[n] = entries[n].second;
  // Raise the bounds the walks skip by.
  constexpr int kB2 = kBlock * kBlock;
  for (const auto& [c, k] : entries) {
    const float top = walls.line(k).maxTop;
    float& b = blockTop[c / size_t(kB2)];
    b = std::max(b, top);
    maxTop = std::max(maxTop, double(top));
  }
}

namespace {

std::unique_ptr<const StaticWorld> solidsOnly(const Scene& scene) {
  StaticWorldOptions o;
  o.parts = StaticWorldParts::Solids;
  return std::make_unique<const StaticWorld>(buildStaticWorld(scene, o));
}

}  // namespace

HorizonFusion::HorizonFusion(const Scene& scene, const HorizonFusionOptions& options)
    : HorizonFusion(scene, solidsOnly(scene), nullptr, options) {}

HorizonFusion::HorizonFusion(const Scene& scene, const StaticWorld& world,
                             const HorizonFusionOptions& options)
    : HorizonFusion(scene, nullptr, &world, options) {}

HorizonFusion::HorizonFusion(const Scene& scene, std::unique_ptr<const StaticWorld> owned,
                             const StaticWorld* borrowed, const HorizonFusionOptions& options)
    : options_(options) {
  const StaticWorld& world = borrowed ? *borrowed : *owned;
  VS_CHECK(world.triangles && world.rays);
  // The solids part was built (a scene with triangles has components).
  VS_CHECK(world.triangles->size() == 0 || !world.solids.components().empty());
  impl_ = std::make_unique<Impl>(scene, std::move(owned), world);
  VS_CHECK(std::isfinite(options.epsilon) && options.epsilon > 0.0);
  VS_CHECK(std::isfinite(options.gridSize) && options.gridSize > 0.0);
  VS_CHECK(std::isfinite(options.binMargin) && options.binMargin > 0.0);
  VS_CHECK(options.azimuthBins >= 8);
  VS_CHECK(options.refinements >= 0 && options.refinements <= 4);
  Stopwatch sw;
  impl_->build(options);
  prepareMs_ = sw.ms();
}

HorizonFusion::~HorizonFusion() = default;

double HorizonFusion::gridSize() const {
  return impl_->g;
}
size_t HorizonFusion::solidColumns() const {
  return impl_->solidColumns;
}
size_t HorizonFusion::wallLines() const {
  return impl_->walls.size();
}

namespace {

// The per-call state of HorizonFusion::cull, one named step per phase.
struct HorizonQuery {
  const HorizonFusion::Impl& w;
  const Box3f& cell;
  HorizonFusionStats& stats;
  std::vector<IRect> excluded;  // shrunk columns that must not occlude
  // The horizon of the current sample at each level of bins (level l has
  // kRefine^l times the bins of level 0 and reaches as many times farther),
  // traced lazily by bin.
  // A bin's walk along its central ray, resumed where a face needs it to
  // reach farther: `steps` are those of the columns entered before `tin`.
  // Everything the walk carries from column to column is kept, so a walk
  // resumed several times takes the same steps, bit for bit, as one made at
  // once.
  struct Walk {
    std::vector<Step> steps;
    glm::dvec2 dir{1.0, 0.0};    // the bin's central direction (x, z)
    int i = 0, j = 0;            // the column the walk is in
    double tx = 0.0, tz = 0.0;   // ray distances to its next X and Z column sides
    double tin = 0.0, t1 = 0.0;  // where the column is entered; where the walk ends
    double best = -kInf;         // the slope of the last step
    int block = -1;              // the block whose bound the walk last took
    int super = -1;              // the super-block whose bound it last took
    bool done = false;           // nothing farther can add a step
    // Wall steps (proof, step 7) not yet taken, by distance: a wall's step
    // lies beyond the column it was found in, and joins `steps` once the
    // walk has entered every column before its distance, so that it never
    // stands in the way of a nearer, lower step.
    std::vector<Step> pending;
  };
  struct Level {
    const HorizonFusion::Impl::BinTable* table = nullptr;
    double reach = 0.0;
    std::vector<uint32_t> traced;  // generation that started each bin's walk
    std::vector<Walk> bins;
    // Per bin, the distance of the step that last hid a face in it (from
    // this sample or an earlier one; negative: none yet).
    std::vector<double> hint;
    std::vector<uint32_t> pieceTraced;  // generation that read each bin's piece
    std::vector<Walk> pieces;
  };
  std::vector<Level> levels;
  glm::dvec3 s{0.0};
  uint32_t generation = 0;
  std::vector<glm::dvec3> poly, tmp;  // scratch for clipping faces to bins
  bool skipBlocks = true;             // HorizonFusionOptions::skipBlocks
  bool hidingHints = true;            // HorizonFusionOptions::hidingHints
  // Metres before and after a bin's last hiding distance that its piece of
  // walk covers: samples of a cell are at most a few metres apart.
  static constexpr double kHintBefore = 4.0, kHintAfter = 2.0;

  // Proof, step 2: enclosures whose floor the cell reaches down to.
  void excludeSolidsBelowTheCell() {
    const double bottom = double(cell.lo.y) - w.margin;
    for (size_t c = 0; c < w.hasColumns.size(); ++c)
      if (w.hasColumns[c] && bottom <= w.floorOf(uint32_t(c))) {
        excluded.push_back(w.rectOf(w.solids.enclosureBounds(uint32_t(c)), w.window + 1));
        ++stats.excludedSolids;
      }
  }

  bool isExcluded(int i, int j) const {
    for (const IRect& r : excluded)
      if (i >= r.i0 && i <= r.i1 && j >= r.j0 && j <= r.j1) return true;
    return false;
  }

  // Proof, step 5: starts the walk of bin k along the bin's central ray
  // over the shrunk columns (Amanatides and Woo's grid walk).
  // A piece of walk (`from` > 0 or `to` finite: the columns between those
  // distances only) is not counted as a bin traced.
  void start(const Level& level, size_t k, Walk& walk, double from = 0.0, double to = kInf,
             bool piece = false) {
    walk.steps.clear();
    walk.pending.clear();
    walk.best = -kInf;
    walk.block = -1;
    walk.super = -1;
    walk.done = true;
    if (!piece) ++stats.horizonBins;
    const glm::dvec2 dir = level.table->centre[k];
    walk.dir = dir;
    const glm::dvec2 org(s.x, s.z);
    // Enter the grid's rectangle.
    const glm::dvec2 glo = w.lo, ghi = w.lo + glm::dvec2(w.nx, w.nz) * w.g;
    double t0 = from, t1 = std::min(to, level.reach);
    for (int a = 0; a < 2; ++a) {
      if (dir[a] == 0.0) {
        if (org[a] < glo[a] || org[a] > ghi[a]) return;
        continue;
      }
      double ta = (glo[a] - org[a]) / dir[a], tb = (ghi[a] - org[a]) / dir[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    if (!(t0 < t1)) return;
    const glm::dvec2 p0 = org + t0 * dir;
    walk.i = std::clamp(int(std::floor((p0.x - glo.x) / w.g)), 0, w.nx - 1);
    walk.j = std::clamp(int(std::floor((p0.y - glo.y) / w.g)), 0, w.nz - 1);
    const int si = dir.x > 0 ? 1 : -1, sj = dir.y > 0 ? 1 : -1;
    walk.tx = dir.x != 0.0 ? (glo.x + (walk.i + (si > 0)) * w.g - org.x) / dir.x : kInf;
    walk.tz = dir.y != 0.0 ? (glo.y + (walk.j + (sj > 0)) * w.g - org.y) / dir.y : kInf;
    walk.tin = t0;
    walk.t1 = t1;
    walk.done = false;
  }

  // Takes the walk's pending wall steps (proof, step 7) up to distance
  // `upTo`, in order, each that rises above `best`, up to the first that
  // hides (the last step taken is then the hiding one, which binHides
  // remembers as the bin's hint); true if one hid.
  template <class Hides>
  static bool takePending(Walk& walk, double upTo, double& best, Hides& hides) {
    bool found = false;
    size_t n = 0;
    for (; n < walk.pending.size() && walk.pending[n].d <= upTo && !found; ++n) {
      Step st = walk.pending[n];
      if (!(st.slope > best)) continue;
      // Distances never fall along the steps (hidingStep searches them):
      // a wall step taken after a column step that ends farther takes that
      // distance, and hides less.
      if (!walk.steps.empty()) st.d = std::max(st.d, walk.steps.back().d);
      walk.steps.push_back(st);
      best = st.slope;
      found = hides(st);
    }
    walk.pending.erase(walk.pending.begin(), walk.pending.begin() + long(n));
    return found;
  }

  // Proof, step 5, lazily: walks a bin on until it has every step closer
  // than `until` (or the walk is done), or, earlier, until a new step
  // satisfies `hides`. The steps come out as the whole walk would make them:
  // walking a prefix changes none.
  template <class Hides>
  bool advance(const Level& level, Walk& walk, double until, Hides&& hides) {
    // Wall steps a finished walk left waiting after the step that hid a face.
    if (walk.done) return takePending(walk, kInf, walk.best, hides);
    if (walk.tin >= until) return false;
    const glm::dvec2 dir = walk.dir;
    const glm::dvec2 org(s.x, s.z);
    const glm::dvec2 glo = w.lo;
    const double reach = level.reach, t1 = walk.t1;
    int i = walk.i, j = walk.j;
    double tx = walk.tx, tz = walk.tz, tin = walk.tin, best = walk.best;
    const int si = dir.x > 0 ? 1 : -1, sj = dir.y > 0 ? 1 : -1;
    // Reciprocals: the walk below multiplies instead of dividing.
    const double invX = dir.x != 0.0 ? 1.0 / dir.x : 0.0, invZ = dir.y != 0.0 ? 1.0 / dir.y : 0.0;
    const double invG = 1.0 / w.g;
    const double dtx = dir.x != 0.0 ? w.g / std::abs(dir.x) : kInf;
    const double dtz = dir.y != 0.0 ? w.g / std::abs(dir.y) : kInf;
    const double y = s.y, lowest = double(cell.lo.y) - w.margin;
    int block = walk.block, super = walk.super;
    bool done = false, found = false;
    // Into the next column along the ray; false once it leaves the grid.
    auto stepToNextColumn = [&] {
      if (tx < tz) {
        i += si;
        tx += dtx;
      } else {
        j += sj;
        tz += dtz;
      }
      return i >= 0 && j >= 0 && i < w.nx && j < w.nz;
    };
    // A rectangle of columns [c0x, c1x) x [c0z, c1z) holding the walk's
    // column, none of whose columns can raise the horizon, is walked without
    // reading its columns: a top h adds a step only with a slope above
    // `best`, at most (h - y) / tin when h > y, and at most (h - y) / (the
    // rectangle's exit, or the reach) otherwise. The walk then jumps to the
    // column just past the exit point (or steps one column when rounding
    // keeps it inside: `again` is set, and the rectangle is tested anew from
    // there).
    enum class Pass { Read, Moved, Done };
    auto passColumns = [&](float top, int c0x, int c0z, int c1x, int c1z, bool& again) {
      again = false;
      const double h = top;
      double exit = t1;
      if (dir.x != 0.0) exit = std::min(exit, (glo.x + (si > 0 ? c1x : c0x) * w.g - org.x) * invX);
      if (dir.y != 0.0) exit = std::min(exit, (glo.y + (sj > 0 ? c1z : c0z) * w.g - org.y) * invZ);
      const double bound = h == double(kNoTop) ? -kInf
                                               : (h > y ? (tin > 1e-9 ? (h - y) / tin : kInf)
                                                        : (h - y) / std::max(exit, 1e-9));
      if (bound > best) return Pass::Read;
      if (exit >= t1) return Pass::Done;
      const glm::dvec2 p = org + (exit + 1e-7 * w.g) * dir;
      const int ni = int(std::floor((p.x - glo.x) * invG));
      const int nj = int(std::floor((p.y - glo.y) * invG));
      if (ni < 0 || nj < 0 || ni >= w.nx || nj >= w.nz) return Pass::Done;
      if (ni >= c0x && ni < c1x && nj >= c0z && nj < c1z) {
        tin = std::min({tx, tz, t1});
        if (!stepToNextColumn()) return Pass::Done;
        again = true;
        return Pass::Moved;
      }
      i = ni;
      j = nj;
      tin = exit;
      tx = dir.x != 0.0 ? (glo.x + (i + (si > 0)) * w.g - org.x) * invX : kInf;
      tz = dir.y != 0.0 ? (glo.y + (j + (sj > 0)) * w.g - org.y) * invZ : kInf;
      return Pass::Moved;
    };
    // The same for the region (ri, rj) of `size` x `size` columns.
    auto passRegion = [&](float top, int ri, int rj, int size, bool& again) {
      return passColumns(top, ri * size, rj * size, (ri + 1) * size, (rj + 1) * size, again);
    };
    constexpr int kB = HorizonFusion::Impl::kBlock, kS = kB * HorizonFusion::Impl::kSuper;
    for (;;) {
      if (found) break;
      if (!walk.pending.empty()) found = takePending(walk, tin, best, hides);
      if (!(tin < t1)) {
        done = true;
        break;
      }
      if (tin >= until || found) break;
      const int b = (j / kB) * w.bx + i / kB;
      if (b != block && skipBlocks) {
        block = b;
        bool again = false;
        const int c = (j / kS) * w.sx + i / kS;
        Pass pass = Pass::Read;
        if (c != super) {
          super = c;
          pass = passRegion(w.superTop[size_t(c)], i / kS, j / kS, kS, again);
          if (again) super = -1;
        }
        if (pass == Pass::Read) {
          const int bi = i / kB, bj = j / kB;
          if (const int r = w.emptyReach[size_t(b)]; r > 1) {
            // Every block within r - 1 of this one is empty too.
            pass = passColumns(kNoTop, (bi - r + 1) * kB, (bj - r + 1) * kB, (bi + r) * kB,
                               (bj + r) * kB, again);
          } else {
            pass = passRegion(w.blockTop[size_t(b)], bi, bj, kB, again);
          }
        }
        if (pass == Pass::Done) {
          done = true;
          break;
        }
        if (pass == Pass::Moved) {
          if (again) block = -1;
          continue;
        }
      }
      const double tout = std::min({tx, tz, t1});
      ++stats.columnSteps;
      const size_t c = w.columnIndex(i, j);
      const HorizonFusion::Impl::Column& column = w.columns[c];
      const double h = column.top;
      if (h != double(kNoTop) && double(column.base) <= lowest && !isExcluded(i, j)) {
        Step st{0.0, 0.0, double(column.base)};
        if (h > y) {
          st.d = tin;
          st.slope = tin > 1e-9 ? (h - y) / tin : -kInf;
        } else {
          st.d = std::min(tout, reach);
          st.slope = (h - y) / st.d;
        }
        if (st.slope > best) {
          walk.steps.push_back(st);
          best = st.slope;
          found = hides(st);
        }
      }
      for (uint32_t n = column.firstWall; n < w.columns[c + 1].firstWall; ++n)
        wallStep(w.wallLineIds[n], org, dir, tin, tout, reach, walk.pending);
      // Nothing farther can rise above `best`: every later square starts at
      // tout or beyond and no top exceeds maxTop.
      if (w.maxTop > y && best * tout >= w.maxTop - y) {
        done = true;
        break;
      }
      if (!stepToNextColumn()) {
        done = true;
        break;
      }
      tin = tout;
    }
    if (done && !found) found = takePending(walk, kInf, best, hides);
    walk.i = i;
    walk.j = j;
    walk.tx = tx;
    walk.tz = tz;
    walk.tin = tin;
    walk.best = best;
    walk.block = block;
    walk.super = super;
    walk.done = done;
    return found;
  }

  // Proof, step 7: the step of wall line k if the central ray from org
  // along dir crosses it between tin and tout, into `pending` (kept sorted
  // by distance).
  void wallStep(uint32_t k, glm::dvec2 org, glm::dvec2 dir, double tin, double tout, double reach,
                std::vector<Step>& pending) {
    const WallLine& line = w.walls.line(k);
    const double den = glm::dot(line.n, dir);
    const double sine = std::abs(den);
    if (!(sine >= HorizonFusion::Impl::kMinWallSine)) return;
    const double d0 = (line.c - glm::dot(line.n, org)) / den;
    if (!(d0 >= tin - w.margin && d0 <= tout + w.margin)) return;
    const double delta = (w.shrinkRadius + 2.0 * w.wallTolerance()) / sine;
    if (!(d0 - delta > 1e-9) || !(d0 + delta <= reach)) return;
    const double u = glm::dot(line.t, org + d0 * dir);
    const std::optional<glm::dvec2> cover = w.walls.cover(k, u - delta, u + delta);
    std::optional<Step> st;
    if (cover) {
      if (cover->x > double(cell.lo.y) - w.margin) return;
      const double y = s.y, top = cover->y;
      st =
          Step{d0 + delta, top > y ? (top - y) / (d0 + delta) : (top - y) / (d0 - delta), cover->x};
      ++stats.wallSteps;
    } else if (w.wallChains) {
      st = chainStep(k, u, org, dir, reach);
      if (!st) return;
      ++stats.chainSteps;
    } else {
      return;
    }
    auto at = std::upper_bound(pending.begin(), pending.end(), st->d,
                               [](double d, const Step& p) { return d < p.d; });
    pending.insert(at, *st);
  }

  // Proof, step 8: what a chain of joined wall lines holds, from where the
  // central ray crosses the first of them out to the sides of the strip.
  struct Chain {
    double base = -kInf, top = kInf;   // heights covered all along it
    double amin = kInf, amax = -kInf;  // its extent along the central ray
  };
  static constexpr int kMaxJoints = 3;

  // The step of a chain through the crossing (tangential coordinate u) of
  // the central ray from org along dir with wall line k that leaves the
  // strip of half-width r + 2 tau around the ray on both sides, one on
  // each, in its heights and extent; nothing when there is none.
  std::optional<Step> chainStep(uint32_t k, double u, glm::dvec2 org, glm::dvec2 dir,
                                double reach) const {
    const double rp = w.shrinkRadius + 2.0 * w.wallTolerance();
    const std::optional<uint32_t> run = w.walls.runOf(k, u);
    if (!run) return std::nullopt;
    // Way 0 along the line's tangent leaves by the side `first`, way 1 by
    // the other; the side the line itself heads for first.
    const double heads = glm::dot(glm::dvec2(-dir.y, dir.x), w.walls.line(k).t);
    std::optional<Chain> chain;
    for (const int first : {heads >= 0.0 ? 1 : -1, heads >= 0.0 ? -1 : 1}) {
      const std::optional<Chain> way0 =
          follow(k, *run, u, 1, first, 0, Chain{}, org, dir, rp, reach);
      if (!way0) continue;
      chain = follow(k, *run, u, -1, -first, 0, *way0, org, dir, rp, reach);
      if (chain) break;
    }
    if (!chain) return std::nullopt;
    const double near = chain->amin - rp, far = chain->amax + rp, y = s.y;
    return Step{far, chain->top > y ? (chain->top - y) / far : (chain->top - y) / near,
                chain->base};
  }

  // Follows run `run` of line k from tangential coordinate u in direction
  // sign (+1: the line's tangent), through at most kMaxJoints - joints more
  // joints, until it leaves the strip |perp . (x - org)| <= rp by the side
  // `side` (the sign of perp . x there); `acc` grown by the pieces
  // followed. Nothing when no way does, a piece is not covered, its base is
  // not below the cell, or the chain comes within rp of the sample or of
  // the reach.
  std::optional<Chain> follow(uint32_t k, uint32_t run, double u, int sign, int side, int joints,
                              Chain acc, glm::dvec2 org, glm::dvec2 dir, double rp,
                              double reach) const {
    const WallLine& line = w.walls.line(k);
    const glm::dvec2 perp(-dir.y, dir.x), m = double(sign) * line.t;
    const double b = glm::dot(perp, line.at(u) - org), rate = glm::dot(perp, m);
    double length = kInf;
    int leaves = 0;
    if (rate > 1e-9) {
      length = std::max(0.0, (rp - b) / rate);
      leaves = 1;
    } else if (rate < -1e-9) {
      length = std::max(0.0, (-rp - b) / rate);
      leaves = -1;
    }
    const double end = sign > 0 ? w.walls.run(run).ub : w.walls.run(run).ua;
    const bool out = length <= double(sign) * (end - u);
    const double u2 = out ? u + double(sign) * length : end;
    const std::optional<glm::dvec2> cover = w.walls.cover(k, std::min(u, u2), std::max(u, u2));
    if (!cover) return std::nullopt;
    acc.base = std::max(acc.base, cover->x);
    acc.top = std::min(acc.top, cover->y);
    if (!(acc.base <= double(cell.lo.y) - w.margin) || !(acc.top > acc.base)) return std::nullopt;
    for (double v : {u, u2}) {
      const double a = glm::dot(dir, line.at(v) - org);
      acc.amin = std::min(acc.amin, a);
      acc.amax = std::max(acc.amax, a);
    }
    if (!(acc.amin - rp > 1e-9) || !(acc.amax + rp <= reach)) return std::nullopt;
    if (out) {
      if (leaves != side) return std::nullopt;
      return acc;
    }
    if (joints == kMaxJoints) return std::nullopt;
    for (const WallJoint& j : w.walls.joints(run, sign > 0 ? 1 : 0)) {
      const WallRun& next = w.walls.run(j.run);
      for (int s2 : {1, -1}) {
        if (double(s2) * ((s2 > 0 ? next.ub : next.ua) - j.u) <= 1e-9) continue;
        if (auto r = follow(j.line, j.run, j.u, s2, side, joints + 1, acc, org, dir, rp, reach))
          return r;
      }
    }
    return std::nullopt;
  }

  // Proof, step 6, for one step: does it hide points at horizontal
  // distance at least rmin, of elevation slope at most `slope` and at
  // least minY high?
  bool stepHides(const Step& st, double rmin, double slope, double minY) const {
    if (!(st.slope > slope) || !(st.d < rmin * (1.0 - 1e-9))) return false;
    if (minY >= st.base) return true;
    const double a = double(cell.lo.y) - st.base;
    return a > 0.0 && st.d * (a + st.base - minY) <= rmin * a * (1.0 - 1e-9);
  }

  // The last of `steps` (a horizon's, slopes rising) that hides points at
  // horizontal distance at least rmin, of slope at most `slope` and at least
  // minY high; null if none.
  const Step* hidingStep(const std::vector<Step>& steps, double rmin, double slope,
                         double minY) const {
    // Only the steps nearer than rmin can hide, and distances never fall
    // along a horizon (takePending).
    const double bound = rmin * (1.0 - 1e-9);
    size_t lo = 0, hi = steps.size();
    while (lo < hi) {
      const size_t mid = (lo + hi) / 2;
      if (steps[mid].d < bound)
        lo = mid + 1;
      else
        hi = mid;
    }
    for (size_t n = lo; n-- > 0;) {
      const Step& st = steps[n];
      if (!(st.slope > slope)) break;  // earlier steps are lower still
      if (stepHides(st, rmin, slope, minY)) return &st;
    }
    return nullptr;
  }

  // Proof, step 6, within one bin. Until the bin's walk is needed for this
  // sample: the steps of a piece of walk around the distance where a step
  // last hid a face in it (every column the central ray crosses within the
  // reach gives a step, step 5, wherever the walk starts), read once per
  // sample. Then the walk's steps so far, then the walk on to rmin,
  // stopping at the first step that hides.
  bool binHides(Level& level, size_t k, double rmin, double slope, double minY) {
    Walk& walk = level.bins[k];
    if (hidingHints && level.traced[k] != generation && level.hint[k] >= 0.0) {
      Walk& piece = level.pieces[k];
      if (level.pieceTraced[k] != generation) {
        level.pieceTraced[k] = generation;
        const double d = level.hint[k];
        start(level, k, piece, std::max(0.0, d - kHintBefore), d + kHintAfter, true);
        advance(level, piece, kInf, [](const Step&) { return false; });
      }
      if (hidingStep(piece.steps, rmin, slope, minY)) return true;
    }
    if (level.traced[k] != generation) {
      start(level, k, walk);
      level.traced[k] = generation;
    }
    if (const Step* st = hidingStep(walk.steps, rmin, slope, minY)) {
      level.hint[k] = st->d;
      return true;
    }
    const bool found = advance(level, walk, rmin,
                               [&](const Step& st) { return stepHides(st, rmin, slope, minY); });
    if (found) level.hint[k] = walk.steps.back().d;
    return found;
  }

  // An upper bound of the elevation slope of points at horizontal distance
  // in [rmin, rmax] and at most maxY high, seen from the sample.
  double faceSlope(double maxY, double rmin, double rmax) const {
    return maxY > s.y ? (maxY - s.y) / rmin : (maxY - s.y) / rmax;
  }

  // Proof, step 6, for bin b of level `lv` (b counts from angle 0 and may
  // lie outside [0, bins)): is the part of face f in the bin's wedge hidden?
  // (rmin, slope, minY) bound the part; `whole` says they are the face's own
  // bounds and the face lies in this bin only. The whole face's bounds
  // first; then those of the part inside the wedge (its nearest, highest and
  // farthest points there); failing both, the kRefine bins of the next
  // level that split this one, which reach kRefine times farther, must each
  // hide their part.
  bool wedgeHides(size_t lv, long b, uint32_t f, double rmin, double slope, double minY,
                  bool whole) {
    Level& level = levels[lv];
    const long nb = long(level.bins.size());
    const size_t k = size_t(((b % nb) + nb) % nb);
    bool hiddenHere = binHides(level, k, rmin, slope, minY);
    if (!hiddenHere && !whole) {
      double bmin = kInf, bmax = 0.0, bminY = kInf, bmaxY = -kInf;
      for (uint32_t n = w.faceStart[f]; n < w.faceStart[f + 1]; ++n) {
        const uint32_t t = w.faceTris[n];
        poly.clear();
        for (int v = 0; v < 3; ++v) poly.push_back(glm::dvec3(w.tris.vertex(t, v)) - s);
        clipToHalfSpace(poly, tmp, level.table->lowSide[k], 0.0);
        clipToHalfSpace(poly, tmp, level.table->highSide[k], 0.0);
        for (size_t v = 0; v < poly.size(); ++v) {
          const glm::dvec3& a = poly[v];
          const glm::dvec3& c = poly[(v + 1) % poly.size()];
          bmin = std::min(bmin, pointSegmentDistance({0.0, 0.0}, {a.x, a.z}, {c.x, c.z}));
          bmax = std::max(bmax, glm::length(glm::dvec2(a.x, a.z)));
          bminY = std::min(bminY, a.y + s.y);
          bmaxY = std::max(bmaxY, a.y + s.y);
        }
      }
      if (bmaxY == -kInf) return true;  // the face does not reach into this bin
      if (!(bmin > 1e-6)) return false;
      rmin = bmin;
      slope = faceSlope(bmaxY, bmin, bmax);
      minY = bminY;
      hiddenHere = binHides(level, k, rmin, slope, minY);
    }
    if (hiddenHere) return true;
    if (lv + 1 >= levels.size()) return false;
    constexpr long kRefine = HorizonFusion::kRefine;
    for (long sb = b * kRefine; sb < (b + 1) * kRefine; ++sb)
      if (!wedgeHides(lv + 1, sb, f, rmin, slope, minY, false)) return false;
    return true;
  }

  // Proof, step 6: is the face hidden from the current sample?
  bool faceHidden(uint32_t f) {
    const glm::dvec2 sh(s.x, s.z);
    double a0 = 0.0, amin = 0.0, amax = 0.0, rmin = kInf, rmax = 0.0, minY = kInf, maxY = -kInf;
    bool first = true;
    for (uint32_t k = w.faceStart[f]; k < w.faceStart[f + 1]; ++k) {
      const uint32_t t = w.faceTris[k];
      for (int v = 0; v < 3; ++v) {
        const glm::dvec3 p(w.tris.vertex(t, v));
        const glm::dvec2 ph(p.x, p.z);
        const glm::dvec2 q = ph - sh;
        const double ang = std::atan2(q.y, q.x);
        if (first) {
          a0 = ang;
          first = false;
        } else {
          double da = ang - a0;
          if (da > std::numbers::pi) da -= 2.0 * std::numbers::pi;
          if (da < -std::numbers::pi) da += 2.0 * std::numbers::pi;
          amin = std::min(amin, da);
          amax = std::max(amax, da);
        }
        rmax = std::max(rmax, glm::length(q));
        minY = std::min(minY, p.y);
        maxY = std::max(maxY, p.y);
        const glm::dvec3 n(w.tris.vertex(t, (v + 1) % 3));
        rmin = std::min(rmin, pointSegmentDistance(sh, ph, {n.x, n.z}));
      }
    }
    if (first || amax - amin >= std::numbers::pi - 1e-6 || !(rmin > 1e-6)) return false;
    const double binWidth = levels[0].table->binWidth;
    const long b0 = long(std::floor((a0 + amin - 1e-9) / binWidth));
    const long b1 = long(std::floor((a0 + amax + 1e-9) / binWidth));
    for (long b = b0; b <= b1; ++b)
      if (!wedgeHides(0, b, f, rmin, faceSlope(maxY, rmin, rmax), minY, b0 == b1)) return false;
    return true;
  }
};

}  // namespace

HorizonFusionResult HorizonFusion::cull(const Box3f& cell,
                                        std::span<const uint32_t> candidates) const {
  VS_CHECK(!cell.empty());
  VS_CHECK(std::isfinite(cell.lo.x) && std::isfinite(cell.lo.y) && std::isfinite(cell.lo.z) &&
           std::isfinite(cell.hi.x) && std::isfinite(cell.hi.y) && std::isfinite(cell.hi.z));
  Stopwatch sw;
  HorizonFusionResult r;
  r.stats.candidateFaces = candidates.size();
  const Impl& w = *impl_;
  HorizonQuery q{
      w, cell, r.stats, {}, {}, {}, 0, {}, {}, options_.skipBlocks, options_.hidingHints};
  // Faces that can be tested: static faces of this scene.
  std::vector<uint32_t> hidden;
  for (uint32_t f : candidates)
    if (f < w.scene.faceCount && w.faceStart[f] < w.faceStart[f + 1]) hidden.push_back(f);
  if (w.nx > 0 && !hidden.empty()) {
    q.excludeSolidsBelowTheCell();
    for (const HorizonFusion::Impl::BinTable& table : w.binTables) {
      const size_t nbins = table.centre.size();
      HorizonQuery::Level& level = q.levels.emplace_back();
      level.table = &table;
      level.reach = 2.0 * options_.binMargin / table.binWidth;
      level.traced.assign(nbins, 0);
      level.bins.resize(nbins);
      level.hint.assign(nbins, -1.0);
      level.pieceTraced.assign(nbins, 0);
      level.pieces.resize(nbins);
    }
    // Samples: centres of a grid of rectangles of half-diagonal <= epsilon
    // on the top face (proof, step 4).
    const glm::dvec3 clo(cell.lo), chi(cell.hi);
    const double side = options_.epsilon * std::numbers::sqrt2;
    const int sx = std::max(1, int(std::ceil((chi.x - clo.x) / side)));
    const int sz = std::max(1, int(std::ceil((chi.z - clo.z) / side)));
    std::vector<uint32_t> still;
    for (int a = 0; a < sx && !hidden.empty(); ++a)
      for (int b = 0; b < sz && !hidden.empty(); ++b) {
        q.s = glm::dvec3(clo.x + (a + 0.5) * (chi.x - clo.x) / sx, chi.y,
                         clo.z + (b + 0.5) * (chi.z - clo.z) / sz);
        ++q.generation;
        ++r.stats.samples;
        still.clear();
        for (uint32_t f : hidden)
          if (q.faceHidden(f)) still.push_back(f);
        hidden.swap(still);
      }
  } else {
    hidden.clear();
  }
  // The result: candidates minus the faces hidden from every sample (both sorted).
  r.faces.reserve(candidates.size() - hidden.size());
  size_t h = 0;
  for (uint32_t f : candidates) {
    while (h < hidden.size() && hidden[h] < f) ++h;
    if (h < hidden.size() && hidden[h] == f) continue;
    r.faces.push_back(f);
  }
  r.stats.culled = candidates.size() - r.faces.size();
  r.stats.timeMs = sw.ms();
  return r;
}

std::optional<FusionChoice> parseFusionChoice(const std::string& text) {
  if (text == "auto") return FusionChoice::Auto;
  if (text == "horizons") return FusionChoice::Horizons;
  if (text == "none") return FusionChoice::None;
  return std::nullopt;
}

std::unique_ptr<HorizonFusion> makeHorizonFusion(const Scene& scene, FusionChoice choice,
                                                 const StaticWorld* world) {
  if (choice == FusionChoice::None) return nullptr;
  Stopwatch clock;
  auto horizons = world ? std::make_unique<HorizonFusion>(scene, *world)
                        : std::make_unique<HorizonFusion>(scene);
  spdlog::info("occlusion horizons: {} solid columns of {:.2f} m, {} wall lines, built in {:.1f} s",
               horizons->solidColumns(), horizons->gridSize(), horizons->wallLines(),
               clock.ms() / 1000.0);
  // Walls alone (interiors: rooms are no solids) are left to the planar
  // fusion of the face stage: on the interiors the horizons' walls culled
  // nothing more, at twice the time of a cell.
  if (choice == FusionChoice::Auto && horizons->solidColumns() == 0) {
    spdlog::info("no solid columns: the PVS runs without occlusion horizons");
    return nullptr;
  }
  return horizons;
}

}  // namespace vistream
