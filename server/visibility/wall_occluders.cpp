#include "server/visibility/wall_occluders.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "common/core/check.h"

namespace vistream {
namespace {

// A near-vertical triangle and the line through its farthest-apart X/Z
// corners.
struct UprightTriangle {
  uint32_t tri = 0;
  glm::dvec2 n{0.0};
  double c = 0.0, length = 0.0;
  long angleKey = 0, offsetKey = 0;
};

// A member's corners projected on its line: (u, y).
struct Projected {
  glm::dvec2 p[3];
  double ua = 0.0, ub = 0.0;  // u range
};

// The heights a projected triangle holds at tangential coordinate u
// (clamped to its u range): (lowest, highest).
glm::dvec2 heightsAt(const Projected& m, double u) {
  u = std::clamp(u, m.ua, m.ub);
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int k = 0; k < 3; ++k) {
    const glm::dvec2 a = m.p[k], b = m.p[(k + 1) % 3];
    if (a.x == u) {
      lo = std::min(lo, a.y);
      hi = std::max(hi, a.y);
    }
    if (a.x == b.x || u < std::min(a.x, b.x) || u > std::max(a.x, b.x)) continue;
    const double y = a.y + (u - a.x) * (b.y - a.y) / (b.x - a.x);
    lo = std::min(lo, y);
    hi = std::max(hi, y);
  }
  return {lo, hi};
}

// Heights covered by the union of `members` at every u of [p, q], over
// which each member's heightsAt is linear (no corner strictly inside):
// a chain of members, each reaching down to the top of the one before it
// (within `tol`) at both ends, hence everywhere between. (base, top at p,
// top at q): every height from base to the top, linear between p and q,
// is covered; base is infinite when no member covers the span.
glm::dvec3 chainCover(const std::vector<Projected>& all, const std::vector<uint32_t>& members,
                      double p, double q, double tol) {
  struct Ends {
    glm::dvec2 atP, atQ;  // (lo, hi) at p and at q
    bool used = false;
  };
  thread_local std::vector<Ends> ends;
  ends.clear();
  for (uint32_t m : members) ends.push_back({heightsAt(all[m], p), heightsAt(all[m], q)});
  // Start from the member whose bottom is lowest at both ends.
  size_t first = ends.size();
  double base = std::numeric_limits<double>::infinity();
  for (size_t k = 0; k < ends.size(); ++k) {
    const double b = std::max(ends[k].atP.x, ends[k].atQ.x);
    if (b < base) {
      base = b;
      first = k;
    }
  }
  if (first == ends.size()) return {std::numeric_limits<double>::infinity(), 0.0, 0.0};
  ends[first].used = true;
  double topP = ends[first].atP.y, topQ = ends[first].atQ.y;
  // The union covers [base, H(u)] at every u, H linear through (topP,
  // topQ). A member reaching down to H at both ends (hence everywhere
  // between) extends it to [base, its top]: taken when its top is at least
  // H at both ends (preferring the highest), or else when it raises the
  // lower end of H.
  for (;;) {
    size_t next = ends.size();
    bool dominating = false;
    double score = -std::numeric_limits<double>::infinity();
    for (size_t k = 0; k < ends.size(); ++k) {
      const Ends& e = ends[k];
      if (e.used || e.atP.x > topP + tol || e.atQ.x > topQ + tol) continue;
      const bool dominates =
          e.atP.y >= topP && e.atQ.y >= topQ && (e.atP.y > topP || e.atQ.y > topQ);
      const bool raises = std::min(e.atP.y, e.atQ.y) > std::min(topP, topQ);
      if (!dominates && !raises) continue;
      const double sc = dominates ? e.atP.y + e.atQ.y : std::min(e.atP.y, e.atQ.y);
      if (dominates > dominating || (dominates == dominating && sc > score)) {
        dominating = dominates;
        score = sc;
        next = k;
      }
    }
    if (next == ends.size()) break;
    ends[next].used = true;
    topP = ends[next].atP.y;
    topQ = ends[next].atQ.y;
  }
  return {base, topP, topQ};
}

}  // namespace

std::pair<glm::dvec2, glm::dvec2> farthestXzCorners(const FlatTriangles& tris, size_t t) {
  glm::dvec2 p[3];
  for (int k = 0; k < 3; ++k) p[k] = {tris.vertex(t, k).x, tris.vertex(t, k).z};
  glm::dvec2 a = p[0], b = p[1];
  for (int k = 0; k < 3; ++k)
    if (glm::length(p[(k + 1) % 3] - p[k]) > glm::length(b - a)) {
      a = p[k];
      b = p[(k + 1) % 3];
    }
  return {a, b};
}

WallOccluders::WallOccluders(const FlatTriangles& tris, double tolerance, double binSize)
    : binSize_(binSize), tolerance_(tolerance) {
  VS_CHECK(std::isfinite(tolerance) && tolerance > 0.0);
  VS_CHECK(std::isfinite(binSize) && binSize > 0.0);
  const double tol = tolerance;
  // Keys: lines of about the same direction and offset fall together;
  // membership is then checked exactly against a reference line.
  constexpr double kAngleQuantum = 2e-4;  // radians
  const double offsetQuantum = 20.0 * tol;
  std::vector<UprightTriangle> upright;
  for (size_t t = 0; t < tris.size(); ++t) {
    if (tris.degenerate[t]) continue;
    const glm::dvec3 v[3] = {tris.vertex(t, 0), tris.vertex(t, 1), tris.vertex(t, 2)};
    const auto [a, b] = farthestXzCorners(tris, t);
    const double length = glm::length(b - a);
    const double height = std::max({v[0].y, v[1].y, v[2].y}) - std::min({v[0].y, v[1].y, v[2].y});
    if (length < 10.0 * tol || height < 10.0 * tol) continue;
    glm::dvec2 n(a.y - b.y, b.x - a.x);
    n /= length;
    if (n.x < 0.0 || (n.x == 0.0 && n.y < 0.0)) n = -n;
    const double c = glm::dot(n, a);
    bool flat = true;
    for (const glm::dvec3& p : v) flat &= std::abs(glm::dot(n, glm::dvec2(p.x, p.z)) - c) <= tol;
    if (!flat) continue;
    const double angle = std::atan2(n.y, n.x);  // in (-pi/2, pi/2]
    upright.push_back({uint32_t(t), n, c, length, long(std::floor(angle / kAngleQuantum)),
                       long(std::floor(c / offsetQuantum))});
  }
  std::sort(upright.begin(), upright.end(), [](const UprightTriangle& x, const UprightTriangle& y) {
    if (x.angleKey != y.angleKey) return x.angleKey < y.angleKey;
    if (x.offsetKey != y.offsetKey) return x.offsetKey < y.offsetKey;
    if (x.length != y.length) return x.length > y.length;
    return x.tri < y.tri;
  });
  // Groups, key by key: a triangle joins the first group of its key whose
  // reference line (its longest member's) holds all its corners within tol.
  std::vector<std::vector<uint32_t>> groups;
  std::vector<WallLine> refs;
  for (size_t k = 0; k < upright.size();) {
    size_t end = k;
    while (end < upright.size() && upright[end].angleKey == upright[k].angleKey &&
           upright[end].offsetKey == upright[k].offsetKey)
      ++end;
    const size_t firstGroup = groups.size();
    for (; k < end; ++k) {
      const UprightTriangle& u = upright[k];
      size_t g = firstGroup;
      for (; g < groups.size(); ++g) {
        bool on = true;
        for (int m = 0; m < 3; ++m) {
          const glm::vec3 p = tris.vertex(u.tri, m);
          on &= std::abs(glm::dot(refs[g].n, glm::dvec2(p.x, p.z)) - refs[g].c) <= tol;
        }
        if (on) break;
      }
      if (g == groups.size()) {
        groups.emplace_back();
        WallLine& line = refs.emplace_back();
        line.n = u.n;
        line.t = glm::dvec2(-u.n.y, u.n.x);
        line.c = u.c;
      }
      groups[g].push_back(u.tri);
    }
  }
  // Cover of each line, sub-span by sub-span between its members' corners,
  // then bin by bin.
  std::vector<Projected> proj;
  std::vector<double> breaks;
  std::vector<std::vector<uint32_t>> spanMembers;
  std::vector<glm::dvec3> spanCover;
  for (size_t g = 0; g < groups.size(); ++g) {
    WallLine line = refs[g];
    proj.clear();
    breaks.clear();
    for (uint32_t t : groups[g]) {
      Projected m;
      m.ua = std::numeric_limits<double>::infinity();
      m.ub = -m.ua;
      for (int k = 0; k < 3; ++k) {
        const glm::dvec3 p(tris.vertex(t, k));
        m.p[k] = {glm::dot(line.t, glm::dvec2(p.x, p.z)), p.y};
        m.ua = std::min(m.ua, m.p[k].x);
        m.ub = std::max(m.ub, m.p[k].x);
        breaks.push_back(m.p[k].x);
      }
      proj.push_back(m);
    }
    std::sort(breaks.begin(), breaks.end());
    breaks.erase(std::unique(breaks.begin(), breaks.end()), breaks.end());
    if (breaks.size() < 2) continue;
    const size_t spans = breaks.size() - 1;
    spanMembers.assign(spans, {});
    for (uint32_t m = 0; m < proj.size(); ++m) {
      // Sub-spans [p, q] with ua <= p + tol and ub >= q - tol.
      const size_t s0 =
          size_t(std::lower_bound(breaks.begin(), breaks.end(), proj[m].ua - tol) - breaks.begin());
      const size_t s1 = size_t(std::upper_bound(breaks.begin(), breaks.end(), proj[m].ub + tol) -
                               breaks.begin());  // first break beyond ub + tol
      for (size_t s = s0; s + 1 < s1; ++s) spanMembers[s].push_back(m);
    }
    spanCover.assign(spans, glm::dvec3(std::numeric_limits<double>::infinity(), 0.0, 0.0));
    for (size_t s = 0; s < spans; ++s)
      if (!spanMembers[s].empty())
        spanCover[s] = chainCover(proj, spanMembers[s], breaks[s], breaks[s + 1], tol);
    // Bins of binSize from the first corner; a bin takes the worst cover of
    // the sub-spans it overlaps, and none past the last corner.
    line.u0 = breaks.front();
    line.binCount = uint32_t(std::ceil((breaks.back() - breaks.front()) / binSize));
    line.firstBin = uint32_t(bins_.size());
    line.firstTriangle = uint32_t(members_.size());
    line.triangleCount = uint32_t(groups[g].size());
    members_.insert(members_.end(), groups[g].begin(), groups[g].end());
    float maxTop = -std::numeric_limits<float>::infinity();
    size_t s = 0;
    for (uint32_t b = 0; b < line.binCount; ++b) {
      const double x0 = line.u0 + double(b) * binSize, x1 = x0 + binSize;
      glm::vec2 cover(0.0f, -1.0f);
      if (x1 <= breaks.back()) {
        while (s + 1 < spans && breaks[s + 1] <= x0) ++s;
        double base = -std::numeric_limits<double>::infinity(), top = -base;
        for (size_t k = s; k < spans && breaks[k] < x1; ++k) {
          // The top is linear over the sub-span: its lowest over the part
          // inside the bin is at one end of that part.
          const double p = breaks[k], q = breaks[k + 1];
          const double inA = std::max(p, x0), inB = std::min(q, x1);
          auto topAt = [&](double u) {
            return spanCover[k].y + (u - p) / (q - p) * (spanCover[k].z - spanCover[k].y);
          };
          base = std::max(base, spanCover[k].x);
          top = std::min({top, topAt(inA), topAt(inB)});
        }
        // Rounded inward: a millionth of a metre, then to float.
        base += 1e-6;
        top -= 1e-6;
        if (top > base) {
          cover = {std::nextafter(float(base), std::numeric_limits<float>::infinity()),
                   std::nextafter(float(top), -std::numeric_limits<float>::infinity())};
          if (cover.y < cover.x) cover = {0.0f, -1.0f};
        }
      }
      if (cover.y >= cover.x) maxTop = std::max(maxTop, cover.y);
      bins_.push_back(cover);
    }
    if (maxTop == -std::numeric_limits<float>::infinity()) {
      // Nothing covered: the line is dropped.
      bins_.resize(line.firstBin);
      members_.resize(line.firstTriangle);
      continue;
    }
    line.maxTop = maxTop;
    lines_.push_back(line);
  }
}

std::optional<glm::dvec2> WallOccluders::cover(size_t k, double ua, double ub) const {
  const WallLine& line = lines_[k];
  const double b0 = std::floor((ua - line.u0) / binSize_);
  const double b1 = std::floor((ub - line.u0) / binSize_);
  if (!(b0 >= 0.0) || !(b1 < double(line.binCount))) return std::nullopt;
  double base = -std::numeric_limits<double>::infinity(), top = -base;
  for (uint32_t b = uint32_t(b0); b <= uint32_t(b1); ++b) {
    const glm::vec2 c = bins_[line.firstBin + b];
    if (c.y < c.x) return std::nullopt;
    base = std::max(base, double(c.x));
    top = std::min(top, double(c.y));
  }
  if (!(top > base)) return std::nullopt;
  return glm::dvec2(base, top);
}

}  // namespace vistream
