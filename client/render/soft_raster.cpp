#include "client/render/soft_raster.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include "common/core/cpu_dispatch.h"

namespace vistream {
namespace {

constexpr int64_t kSub = 256;   // sub-pixel steps per pixel
constexpr float kGuard = 8.0f;  // guard band, in multiples of w (|x|, |y| <= kGuard * w)
constexpr int kBandRows = 16;   // rows per parallel band
constexpr size_t kSetUpChunk = 4096;
constexpr uint32_t kNoOwner = std::numeric_limits<uint32_t>::max();  // a pixel no triangle drew

using Clip = glm::vec4;

// Clips a convex polygon in homogeneous coordinates against d(v) >= 0.
template <class Dist>
int clipPolygon(const Clip* in, int n, Clip* out, Dist dist) {
  int m = 0;
  for (int i = 0; i < n; ++i) {
    const Clip& a = in[i];
    const Clip& b = in[(i + 1) % n];
    const float da = dist(a), db = dist(b);
    if (da >= 0.0f) out[m++] = a;
    if ((da >= 0.0f) != (db >= 0.0f)) {
      const float t = da / (da - db);
      out[m++] = a + t * (b - a);
    }
  }
  return m;
}

bool isTopLeft(int64_t dx, int64_t dy) {
  return dy < 0 || (dy == 0 && dx > 0);
}

}  // namespace

namespace {

VISTREAM_AVX2_CLONES void coverageOfRange(const uint32_t* ids, size_t n, uint8_t* out) {
  for (size_t p = 0; p < n; ++p)
    out[p] = ids[p] == kNoTriangle       ? uint8_t(kUncovered)
             : ids[p] == kBeyondDistance ? uint8_t(kBeyond)
                                         : uint8_t(kCovered);
}

}  // namespace

void coverageOf(const IdBuffer& ids, std::vector<uint8_t>& covered) {
  covered.resize(ids.ids.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, covered.size(), size_t(1) << 15),
                    [&](const tbb::blocked_range<size_t>& r) {
                      coverageOfRange(ids.ids.data() + r.begin(), r.size(),
                                      covered.data() + r.begin());
                    });
}

void IdBuffer::reset(int w, int h) {
  width = w;
  height = h;
  ids.assign(size_t(w) * size_t(h), kNoTriangle);
  inverseDepth.assign(size_t(w) * size_t(h), 0.0f);
}

void SoftwareRasterizer::setUp(const Camera& camera, const FlatTriangles& triangles,
                               std::span<const uint32_t> which) {
  const glm::mat4 vp = camera.rotationProjection();
  const glm::vec3 eye = camera.eye;
  const float W = float(camera.width), H = float(camera.height);
  const size_t chunks = (which.size() + kSetUpChunk - 1) / kSetUpChunk;
  std::vector<std::vector<ScreenTriangle>> parts(chunks);
  tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
    std::vector<ScreenTriangle>& part = parts[c];
    const size_t end = std::min(which.size(), (c + 1) * kSetUpChunk);
    for (size_t i = c * kSetUpChunk; i < end; ++i) {
      const uint32_t t = which[i];
      if (triangles.degenerate[t]) continue;
      std::array<Clip, 9> a, b;
      int n = 3;
      for (int k = 0; k < 3; ++k) a[size_t(k)] = vp * glm::vec4(triangles.vertex(t, k) - eye, 1.0f);
      // Trivial rejection against each plane, then clipping where needed.
      bool reject = false, needClip = false;
      const auto planes = std::array<glm::vec4, 5>{
          glm::vec4(0, 0, 1, 1), glm::vec4(1, 0, 0, kGuard), glm::vec4(-1, 0, 0, kGuard),
          glm::vec4(0, 1, 0, kGuard), glm::vec4(0, -1, 0, kGuard)};
      for (const glm::vec4& p : planes) {
        int outside = 0;
        for (int k = 0; k < 3; ++k) outside += glm::dot(p, a[size_t(k)]) < 0.0f;
        if (outside == 3) reject = true;
        if (outside > 0) needClip = true;
      }
      // Also reject triangles wholly outside the visible frustum sides (guard-band accepted ones
      // are clipped only against the guard band, which keeps integer coordinates small).
      const auto visible = std::array<glm::vec4, 4>{glm::vec4(1, 0, 0, 1), glm::vec4(-1, 0, 0, 1),
                                                    glm::vec4(0, 1, 0, 1), glm::vec4(0, -1, 0, 1)};
      for (const glm::vec4& p : visible) {
        int outside = 0;
        for (int k = 0; k < 3; ++k) outside += glm::dot(p, a[size_t(k)]) < 0.0f;
        if (outside == 3) reject = true;
      }
      if (reject) continue;
      if (needClip) {
        for (const glm::vec4& p : planes) {
          n = clipPolygon(a.data(), n, b.data(), [&](const Clip& v) { return glm::dot(p, v); });
          std::copy(b.begin(), b.begin() + n, a.begin());
          if (n < 3) break;
        }
        if (n < 3) continue;
      }
      // Project and snap.
      std::array<int64_t, 9> sx, sy;
      std::array<float, 9> sw;
      bool bad = false;
      for (int k = 0; k < n; ++k) {
        const Clip& v = a[size_t(k)];
        if (!(v.w > 0.0f)) {
          bad = true;
          break;
        }
        const float x = (v.x / v.w * 0.5f + 0.5f) * W, y = (0.5f - v.y / v.w * 0.5f) * H;
        sx[size_t(k)] = int64_t(std::llround(double(x) * kSub));
        sy[size_t(k)] = int64_t(std::llround(double(y) * kSub));
        sw[size_t(k)] = 1.0f / v.w;
      }
      if (bad) continue;
      for (int k = 1; k + 1 < n; ++k) {
        ScreenTriangle s;
        const int idx[3] = {0, k, k + 1};
        for (int j = 0; j < 3; ++j) {
          s.x[j] = sx[size_t(idx[j])];
          s.y[j] = sy[size_t(idx[j])];
          s.invW[j] = sw[size_t(idx[j])];
        }
        const int64_t area =
            (s.x[1] - s.x[0]) * (s.y[2] - s.y[0]) - (s.x[2] - s.x[0]) * (s.y[1] - s.y[0]);
        if (area == 0) continue;
        if (area < 0) {
          std::swap(s.x[1], s.x[2]);
          std::swap(s.y[1], s.y[2]);
          std::swap(s.invW[1], s.invW[2]);
        }
        s.id = t;
        // Pixels whose centre (x + 0.5) may lie inside.
        const int64_t lx = std::min({s.x[0], s.x[1], s.x[2]}),
                      hx = std::max({s.x[0], s.x[1], s.x[2]});
        const int64_t ly = std::min({s.y[0], s.y[1], s.y[2]}),
                      hy = std::max({s.y[0], s.y[1], s.y[2]});
        auto firstPixel = [](int64_t lo) {
          return int(std::floor(double(lo - kSub / 2) / double(kSub)));
        };
        s.minX = std::max(0, firstPixel(lx));
        // Half a pixel of margin on the far sides, for coverage with an outset.
        s.maxX = std::min(camera.width - 1, int(std::floor(double(hx) / double(kSub))));
        s.minY = std::max(0, firstPixel(ly));
        s.maxY = std::min(camera.height - 1, int(std::floor(double(hy) / double(kSub))));
        if (s.minX > s.maxX || s.minY > s.maxY) continue;
        part.push_back(s);
      }
    }
  });
  screen_.clear();
  for (auto& p : parts) screen_.insert(screen_.end(), p.begin(), p.end());
}

namespace {

// Walks the rows [y0, y1] of a triangle and calls fn(y, xa, xb, e) for the
// span of pixel centres inside it by the top-left rule, with `extra` more
// distance (in edge-function units) required on each edge; e holds the three
// edge functions at (xa, y) and each falls by dy[k] * kSub a pixel step.
// Edge k runs from vertex k to vertex k+1; E_k(p) = dx*(py-ay) - dy*(px-ax).
struct Edges {
  int64_t dx[3], dy[3], bias[3];
};

inline Edges edgesOf(const int64_t* X, const int64_t* Y, const std::array<int64_t, 3>& extra) {
  Edges g;
  for (int k = 0; k < 3; ++k) {
    const int j = (k + 1) % 3;
    g.dx[k] = X[j] - X[k];
    g.dy[k] = Y[j] - Y[k];
    // E >= 0 on top-left edges, E > 0 (i.e. E - 1 >= 0) on the others.
    g.bias[k] = (isTopLeft(g.dx[k], g.dy[k]) ? 0 : 1) + extra[size_t(k)];
  }
  return g;
}

template <class Fn>
void scanTriangle(const int64_t* X, const int64_t* Y, int minX, int maxX, int y0, int y1,
                  const Edges& g, Fn&& fn) {
  const int64_t px0 = int64_t(minX) * kSub + kSub / 2;
  for (int y = y0; y <= y1; ++y) {
    const int64_t py = int64_t(y) * kSub + kSub / 2;
    int64_t e[3];
    int xa = minX, xb = maxX;
    for (int k = 0; k < 3 && xa <= xb; ++k) {
      // f(x) = e0 - step * (x - minX) >= 0, step = dy * kSub.
      e[k] = g.dx[k] * (py - Y[k]) - g.dy[k] * (px0 - X[k]) - g.bias[k];
      const int64_t step = g.dy[k] * kSub;
      if (step == 0) {
        if (e[k] < 0) xa = maxX + 1;
      } else if (step > 0) {
        // x - minX <= e / step
        if (e[k] < 0)
          xa = maxX + 1;
        else
          xb = int(std::min<int64_t>(xb, int64_t(minX) + e[k] / step));
      } else {
        // x - minX >= -e / -step  (ceil)
        if (e[k] < 0) {
          const int64_t need = (-e[k] + (-step) - 1) / (-step);
          xa = int(std::max<int64_t>(xa, int64_t(minX) + need));
        }
      }
    }
    if (xa > xb) continue;
    int64_t ea[3];
    for (int k = 0; k < 3; ++k) ea[k] = e[k] + g.bias[k] - g.dy[k] * kSub * int64_t(xa - minX);
    fn(y, xa, xb, ea);
  }
}

// Hierarchical depth for one band of rows: per tile of kTileColumns
// columns, the farthest depth (smallest 1/w) drawn in it so far, 0 while a
// pixel is empty. A triangle whose nearest point is nearer than no tile's
// farthest cannot win a pixel there and is skipped. Tiles written since
// their depth was taken are recomputed when next asked.
constexpr int kTileColumns = 32;

class BandDepth {
 public:
  BandDepth(const IdBuffer& out, int y0, int y1)
      : out_(out),
        y0_(y0),
        y1_(y1),
        far_(size_t((out.width + kTileColumns - 1) / kTileColumns), 0.0f),
        stale_(far_.size(), 0) {}
  // Whether every pixel of columns [x0, x1] in the band is nearer than `q`.
  bool hides(int x0, int x1, float q) {
    for (int t = x0 / kTileColumns; t <= x1 / kTileColumns; ++t) {
      if (stale_[size_t(t)]) refresh(t);
      if (!(far_[size_t(t)] > q)) return false;
    }
    return true;
  }
  void written(int x0, int x1) {
    for (int t = x0 / kTileColumns; t <= x1 / kTileColumns; ++t) stale_[size_t(t)] = 1;
  }

 private:
  void refresh(int t) {
    const int x0 = t * kTileColumns, x1 = std::min(out_.width, x0 + kTileColumns);
    float m = std::numeric_limits<float>::infinity();
    for (int y = y0_; y <= y1_; ++y) {
      const float* d = out_.inverseDepth.data() + size_t(y) * size_t(out_.width);
      for (int x = x0; x < x1; ++x) m = std::min(m, d[x]);
    }
    far_[size_t(t)] = m;
    stale_[size_t(t)] = 0;
  }
  const IdBuffer& out_;
  int y0_, y1_;
  std::vector<float> far_;
  std::vector<uint8_t> stale_;
};

}  // namespace

size_t SoftwareRasterizer::fill(const Camera& camera, float insetPx, IdBuffer& out) {
  out.reset(camera.width, camera.height);
  const int W = camera.width;
  const size_t bands = size_t((camera.height + kBandRows - 1) / kBandRows);
  std::vector<std::vector<uint32_t>> bins(bands);
  // An outset reaches past the triangle's bounds: at most 8 outsets (the
  // mitre of a 15 degree corner; sharper corners are cut there).
  const int margin = insetPx < 0.0f ? int(std::ceil(-8.0f * insetPx)) + 1 : 0;
  // Without an outset every fragment lies inside its triangle, so its 1/w is
  // at most the largest of the vertices': triangles are drawn nearest first
  // (a counting sort on that bound's float bits, which order positive
  // floats) and those behind what a band already holds are skipped.
  // Equal depths go to the triangle earlier in `which`, as in any order.
  const bool hierarchical = margin == 0;
  order_.resize(screen_.size());
  if (hierarchical) {
    constexpr int kBuckets = 2048;
    auto bucketOf = [](const ScreenTriangle& t) {
      const float q = std::max({t.invW[0], t.invW[1], t.invW[2]});
      uint32_t bits;
      std::memcpy(&bits, &q, sizeof bits);
      return kBuckets - 1 - int(std::min<uint32_t>(bits >> 20, kBuckets - 1));  // exponent, 3 bits
    };
    std::vector<uint32_t> start(kBuckets + 1, 0);
    for (const ScreenTriangle& t : screen_) ++start[size_t(bucketOf(t)) + 1];
    for (int k = 0; k < kBuckets; ++k) start[size_t(k) + 1] += start[size_t(k)];
    for (uint32_t i = 0; i < screen_.size(); ++i) order_[start[size_t(bucketOf(screen_[i]))]++] = i;
    owner_.assign(out.ids.size(), kNoOwner);
  } else {
    for (uint32_t i = 0; i < screen_.size(); ++i) order_[i] = i;
  }
  for (uint32_t i : order_)
    for (int b = std::max(0, screen_[i].minY - margin) / kBandRows;
         b <= std::min(camera.height - 1, screen_[i].maxY + margin) / kBandRows; ++b)
      bins[size_t(b)].push_back(i);
  std::vector<size_t> skipped(bins.size(), 0);
  tbb::parallel_for(size_t(0), bins.size(), [&](size_t band) {
    const int y0 = int(band) * kBandRows, y1 = std::min(camera.height - 1, y0 + kBandRows - 1);
    BandDepth bandDepth(out, y0, y1);
    for (uint32_t i : bins[band]) {
      const ScreenTriangle& s = screen_[i];
      const int minX = std::max(0, s.minX - margin),
                maxX = std::min(camera.width - 1, s.maxX + margin);
      const int ya2 = std::max(y0, s.minY - margin), yb2 = std::min(y1, s.maxY + margin);
      // A margin for the rounding of the interpolated 1/w.
      const float nearest = std::max({s.invW[0], s.invW[1], s.invW[2]}) * (1.0f + 1e-5f);
      if (hierarchical && bandDepth.hides(minX, maxX, nearest)) {
        ++skipped[band];
        continue;
      }
      const double area =
          double((s.x[1] - s.x[0]) * (s.y[2] - s.y[0]) - (s.x[2] - s.x[0]) * (s.y[1] - s.y[0]));
      std::array<int64_t, 3> extra{};
      if (insetPx != 0.0f)
        for (int k = 0; k < 3; ++k) {
          const int j = (k + 1) % 3;
          const double len = std::hypot(double(s.x[j] - s.x[k]), double(s.y[j] - s.y[k]));
          // Rounded away from the triangle's own edge: an inset never grows, an outset never
          // shrinks.
          const double e = double(insetPx) * double(kSub) * len;
          extra[size_t(k)] = int64_t(insetPx > 0.0f ? std::ceil(e) : std::floor(e));
        }
      const Edges g = edgesOf(s.x, s.y, extra);
      // 1/w is linear in the edge functions: (E1 q0 + E2 q1 + E0 q2) / area
      // (E0 is the edge 0->1, opposite vertex 2, and so on).
      const double dqdx = -(double(g.dy[1]) * s.invW[0] + double(g.dy[2]) * s.invW[1] +
                            double(g.dy[0]) * s.invW[2]) *
                          kSub / area;
      scanTriangle(s.x, s.y, minX, maxX, ya2, yb2, g, [&](int y, int xa, int xb, const int64_t* e) {
        double q =
            (double(e[1]) * s.invW[0] + double(e[2]) * s.invW[1] + double(e[0]) * s.invW[2]) / area;
        const size_t row = size_t(y) * size_t(W);
        float* depth = out.inverseDepth.data() + row;
        uint32_t* ids = out.ids.data() + row;
        // Nearer is a larger 1/w: no division per pixel.
        bool wrote = false;
        if (hierarchical) {
          uint32_t* owner = owner_.data() + row;
          for (int x = xa; x <= xb; ++x, q += dqdx) {
            const float qf = float(q);
            // A tie goes to the earlier triangle, never to the background.
            if (qf > depth[x] || (qf == depth[x] && i < owner[x] && owner[x] != kNoOwner)) {
              depth[x] = qf;
              ids[x] = s.id;
              owner[x] = i;
              wrote = true;
            }
          }
          if (wrote) bandDepth.written(xa, xb);
        } else {
          for (int x = xa; x <= xb; ++x, q += dqdx) {
            const float qf = float(q);
            if (qf > depth[x]) {
              depth[x] = qf;
              ids[x] = s.id;
            }
          }
        }
      });
    }
  });
  return std::accumulate(skipped.begin(), skipped.end(), size_t(0));
}

void SoftwareRasterizer::dropBeyond(const Camera& camera, float maxDistance, IdBuffer& out) {
  if (!std::isfinite(maxDistance)) return;
  const int W = camera.width;
  const Camera::PixelRays rays = camera.pixelRays();
  tbb::parallel_for(0, camera.height, [&](int y) {
    for (int x = 0; x < W; ++x) {
      const size_t p = size_t(y) * size_t(W) + size_t(x);
      if (out.ids[p] == kNoTriangle) continue;
      // rayDirection has a unit component along the view axis, so its
      // length times the view depth is the distance along the ray.
      const float dist =
          glm::length(rays.at(float(x) + 0.5f, float(y) + 0.5f)) / out.inverseDepth[p];
      if (dist > maxDistance) out.ids[p] = kBeyondDistance;
    }
  });
}

RasterStats SoftwareRasterizer::draw(const Camera& camera, const FlatTriangles& triangles,
                                     std::span<const uint32_t> which, IdBuffer& out,
                                     float maxDistance) {
  setUp(camera, triangles, which);
  const size_t skipped = fill(camera, 0.0f, out);
  dropBeyond(camera, maxDistance, out);
  return {which.size(), screen_.size(), skipped};
}

RasterStats SoftwareRasterizer::coverage(const Camera& camera, const FlatTriangles& triangles,
                                         std::span<const uint32_t> which, float insetPx,
                                         std::vector<uint8_t>& covered, float maxDistance) {
  setUp(camera, triangles, which);
  const size_t skipped = fill(camera, insetPx, scratch_);
  dropBeyond(camera, maxDistance * (1.0f - 1e-4f), scratch_);
  coverageOf(scratch_, covered);
  // Pixels some grown triangle reaches are not certainly empty.
  if (insetPx > 0.0f) {
    fill(camera, -insetPx, scratch_);
    for (size_t p = 0; p < covered.size(); ++p)
      if (covered[p] == kUncovered && scratch_.ids[p] != kNoTriangle) covered[p] = kBeyond;
  }
  return {which.size(), screen_.size(), skipped};
}

}  // namespace vistream
