#include "server/visibility/wall_occluders.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <unordered_map>

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

WallOccluders::WallOccluders(const FlatTriangles& tris, double tolerance, double binSize,
                             double jointTolerance)
    : binSize_(binSize), tolerance_(tolerance), jointTolerance_(jointTolerance) {
  VS_CHECK(std::isfinite(tolerance) && tolerance > 0.0);
  VS_CHECK(std::isfinite(binSize) && binSize > 0.0);
  VS_CHECK(std::isfinite(jointTolerance) && jointTolerance > 0.0 && jointTolerance < 0.2);
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
    // Bins of binSize from the first corner to the last (the last bin
    // takes the rest); a bin takes the worst cover of the sub-spans it
    // overlaps, none if one is not covered.
    line.u0 = breaks.front();
    line.u1 = breaks.back();
    line.binCount =
        uint32_t(std::max(1.0, std::ceil((breaks.back() - breaks.front()) / binSize - 1e-9)));
    line.firstBin = uint32_t(bins_.size());
    line.firstTriangle = uint32_t(members_.size());
    line.triangleCount = uint32_t(groups[g].size());
    members_.insert(members_.end(), groups[g].begin(), groups[g].end());
    // The worst cover over [x0, x1] (x0 < x1), rounded inward by a
    // millionth of a metre and then to float; (0, -1): not covered.
    auto worstCover = [&](double x0, double x1) {
      const size_t s0 = size_t(std::upper_bound(breaks.begin(), breaks.end(), x0) -
                               breaks.begin());  // sub-span s0 - 1 holds x0
      double base = -std::numeric_limits<double>::infinity(), top = -base;
      bool any = false;
      for (size_t k = s0 == 0 ? 0 : s0 - 1; k < spans && breaks[k] < x1; ++k) {
        any = true;
        // The top is linear over the sub-span: its lowest over the part
        // inside [x0, x1] is at one end of that part.
        const double p = breaks[k], q = breaks[k + 1];
        const double inA = std::max(p, x0), inB = std::min(q, x1);
        auto topAt = [&](double u) {
          return spanCover[k].y + (u - p) / (q - p) * (spanCover[k].z - spanCover[k].y);
        };
        base = std::max(base, spanCover[k].x);
        top = std::min({top, topAt(inA), topAt(inB)});
      }
      base += 1e-6;
      top -= 1e-6;
      glm::vec2 cover(0.0f, -1.0f);
      if (any && top > base) {
        cover = {std::nextafter(float(base), std::numeric_limits<float>::infinity()),
                 std::nextafter(float(top), -std::numeric_limits<float>::infinity())};
        if (cover.y < cover.x) cover = {0.0f, -1.0f};
      }
      return cover;
    };
    float maxTop = -std::numeric_limits<float>::infinity();
    for (uint32_t b = 0; b < line.binCount; ++b) {
      const double x0 = line.u0 + double(b) * binSize;
      const double x1 = b + 1 == line.binCount ? breaks.back() : x0 + binSize;
      const glm::vec2 cover = x1 > x0 ? worstCover(x0, x1) : glm::vec2(0.0f, -1.0f);
      if (cover.y >= cover.x) maxTop = std::max(maxTop, cover.y);
      bins_.push_back(cover);
    }
    // Runs: the maximal stretches of covered sub-spans, exact to their
    // corners, with the covers of the parts of their first and last bins
    // they hold.
    line.firstRun = uint32_t(runs_.size());
    for (size_t a = 0; a < spans;) {
      if (!std::isfinite(spanCover[a].x)) {
        ++a;
        continue;
      }
      size_t b = a;
      while (b + 1 < spans && std::isfinite(spanCover[b + 1].x)) ++b;
      WallRun run;
      run.ua = breaks[a];
      run.ub = breaks[b + 1];
      a = b + 1;
      const uint32_t head = headBin(line, run.ua), tail = tailBin(line, run.ub);
      const double headEnd = head + 1 == line.binCount ? line.u1 : line.u0 + (head + 1) * binSize;
      run.head = worstCover(run.ua, std::min(run.ub, headEnd));
      run.tail = worstCover(std::max(run.ua, line.u0 + double(tail) * binSize), run.ub);
      if (head == tail) run.tail = run.head;
      if (run.head.y < run.head.x && run.tail.y < run.tail.x && tail <= head + 1) continue;
      runs_.push_back(run);
    }
    line.runCount = uint32_t(runs_.size()) - line.firstRun;
    if (maxTop == -std::numeric_limits<float>::infinity() && line.runCount == 0) {
      // Nothing covered: the line is dropped.
      bins_.resize(line.firstBin);
      members_.resize(line.firstTriangle);
      continue;
    }
    for (uint32_t r = line.firstRun; r < line.firstRun + line.runCount; ++r)
      maxTop = std::max({maxTop, runs_[r].head.y, runs_[r].tail.y});
    line.maxTop = maxTop;
    lines_.push_back(line);
  }
  buildJoints();
}

uint32_t WallOccluders::headBin(const WallLine& line, double u) const {
  const double b = std::floor((u - line.u0) / binSize_);
  return uint32_t(std::clamp(b, 0.0, double(line.binCount) - 1.0));
}

uint32_t WallOccluders::tailBin(const WallLine& line, double u) const {
  const double b = std::ceil((u - line.u0) / binSize_) - 1.0;
  return uint32_t(std::clamp(b, 0.0, double(line.binCount) - 1.0));
}

void WallOccluders::buildJoints() {
  const double tol = jointTolerance_;
  // Run ends hashed by cells of kCell metres; each run is sampled every
  // half cell and the 3 x 3 cells around each sample read, which finds
  // every end within tol (< kCell / 4, checked) of it.
  constexpr double kCell = 1.0;
  auto cellOf = [](glm::dvec2 p) {
    return std::pair{int64_t(std::floor(p.x / kCell)), int64_t(std::floor(p.y / kCell))};
  };
  auto cellKey = [](int64_t ix, int64_t iz) {
    return (uint64_t(ix) << 32) ^ (uint64_t(iz) & 0xffffffffu);
  };
  std::vector<uint32_t> lineOfRun(runs_.size());
  for (size_t k = 0; k < lines_.size(); ++k)
    for (uint32_t r = 0; r < lines_[k].runCount; ++r)
      lineOfRun[lines_[k].firstRun + r] = uint32_t(k);
  auto endPoint = [&](size_t end) {
    const WallRun& run = runs_[end / 2];
    return lines_[lineOfRun[end / 2]].at(end % 2 == 0 ? run.ua : run.ub);
  };
  std::unordered_map<uint64_t, std::vector<uint32_t>> ends;  // cell -> 2 run + end
  for (size_t e = 0; e < 2 * runs_.size(); ++e) {
    const auto [ix, iz] = cellOf(endPoint(e));
    ends[cellKey(ix, iz)].push_back(uint32_t(e));
  }
  std::vector<std::vector<WallJoint>> found(2 * runs_.size());
  std::vector<uint32_t> seenBy(2 * runs_.size(), std::numeric_limits<uint32_t>::max());
  for (uint32_t r = 0; r < runs_.size(); ++r) {
    const WallLine& l = lines_[lineOfRun[r]];
    const double ua = runs_[r].ua - tol, ub = runs_[r].ub + tol;
    const size_t samples = size_t(std::ceil((ub - ua) / (0.5 * kCell))) + 1;
    for (size_t n = 0; n < samples; ++n) {
      const auto [ix, iz] = cellOf(l.at(std::min(ub, ua + 0.5 * kCell * double(n))));
      for (int64_t dz = -1; dz <= 1; ++dz)
        for (int64_t dx = -1; dx <= 1; ++dx) {
          const auto it = ends.find(cellKey(ix + dx, iz + dz));
          if (it == ends.end()) continue;
          for (uint32_t end : it->second) {
            if (lineOfRun[end / 2] == lineOfRun[r] || seenBy[end] == r) continue;
            seenBy[end] = r;
            const glm::dvec2 e = endPoint(end);
            const double u = glm::dot(l.t, e);
            if (std::abs(glm::dot(l.n, e) - l.c) > tol || u < ua || u > ub) continue;
            found[end].push_back({lineOfRun[r], r, std::clamp(u, runs_[r].ua, runs_[r].ub)});
          }
        }
    }
  }
  jointStart_.assign(found.size() + 1, 0);
  for (size_t e = 0; e < found.size(); ++e) {
    jointStart_[e + 1] = jointStart_[e] + uint32_t(found[e].size());
    joints_.insert(joints_.end(), found[e].begin(), found[e].end());
  }
}

std::optional<uint32_t> WallOccluders::runOf(size_t k, double u) const {
  const WallLine& line = lines_[k];
  const auto first = runs_.begin() + line.firstRun, last = first + line.runCount;
  auto it = std::upper_bound(first, last, u, [](double x, const WallRun& r) { return x < r.ua; });
  if (it == first) return std::nullopt;
  --it;
  if (!(u <= it->ub)) return std::nullopt;
  return uint32_t(it - runs_.begin());
}

std::optional<glm::dvec2> WallOccluders::cover(size_t k, double ua, double ub) const {
  if (!(ua <= ub)) return std::nullopt;
  const std::optional<uint32_t> r = runOf(k, ua);
  if (!r || !(ub <= runs_[*r].ub)) return std::nullopt;
  const WallLine& line = lines_[k];
  const WallRun& run = runs_[*r];
  const uint32_t head = headBin(line, run.ua), tail = tailBin(line, run.ub);
  const uint32_t b0 = std::max(head, headBin(line, ua)),
                 b1 = std::min(tail, std::max(b0, tailBin(line, ub)));
  if (b1 < b0) return std::nullopt;  // a point at a run's end on a bin side
  double base = -std::numeric_limits<double>::infinity(), top = -base;
  for (uint32_t b = b0; b <= b1; ++b) {
    const glm::vec2 c = b == head ? run.head : (b == tail ? run.tail : bins_[line.firstBin + b]);
    if (c.y < c.x) return std::nullopt;
    base = std::max(base, double(c.x));
    top = std::min(top, double(c.y));
  }
  if (!(top > base)) return std::nullopt;
  return glm::dvec2(base, top);
}

}  // namespace vistream
