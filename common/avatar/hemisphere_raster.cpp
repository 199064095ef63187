#include "common/avatar/hemisphere_raster.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "common/core/check.h"

namespace vistream {
namespace {

// The cube-map cell centre of face f (0..5: +x, -x, +y, -y, +z, -z) and
// cell (i, j), as a unit vector.
glm::vec3 cellDirection(int face, int i, int j, int side) {
  const float u = (float(i) + 0.5f) / float(side) * 2.0f - 1.0f;
  const float v = (float(j) + 0.5f) / float(side) * 2.0f - 1.0f;
  const float s = face % 2 == 0 ? 1.0f : -1.0f;
  glm::vec3 d;
  switch (face / 2) {
    case 0:
      d = {s, u, v};
      break;
    case 1:
      d = {u, s, v};
      break;
    default:
      d = {u, v, s};
      break;
  }
  return glm::normalize(d);
}

// Sutherland-Hodgman clip of triangle (a, b, c) to z >= 0: 0, 3 or 4 corners.
int clipToUpperHalf(const glm::vec3 in[3], glm::vec3 out[4]) {
  int n = 0;
  for (int k = 0; k < 3; ++k) {
    const glm::vec3& p = in[k];
    const glm::vec3& q = in[(k + 1) % 3];
    const bool pIn = p.z >= 0.0f, qIn = q.z >= 0.0f;
    if (pIn) out[n++] = p;
    if (pIn != qIn) {
      const float t = p.z / (p.z - q.z);
      glm::vec3 x = p + (q - p) * t;
      x.z = 0.0f;
      if (n < 4) out[n++] = x;
    }
  }
  return n;
}

}  // namespace

VisibilityMask::VisibilityMask(int side) : side_(side) {
  VS_CHECK(side >= 8 && side <= 256 && side % 8 == 0);
  bits_.assign((size_t(side) * size_t(side) + 63) / 64, 0);
}

void VisibilityMask::clear() {
  std::fill(bits_.begin(), bits_.end(), 0);
}

size_t VisibilityMask::count() const {
  size_t n = 0;
  for (const uint64_t w : bits_) n += size_t(std::popcount(w));
  return n;
}

bool maskPixelInDisk(int side, int x, int y) {
  const float dx = (float(x) + 0.5f) / float(side) * 2.0f - 1.0f;
  const float dy = (float(y) + 0.5f) / float(side) * 2.0f - 1.0f;
  return dx * dx + dy * dy < 1.0f;
}

glm::vec3 maskDirection(int side, int x, int y) {
  const float dx = (float(x) + 0.5f) / float(side) * 2.0f - 1.0f;
  const float dy = (float(y) + 0.5f) / float(side) * 2.0f - 1.0f;
  return {dx, dy, std::sqrt(std::max(0.0f, 1.0f - dx * dx - dy * dy))};
}

PlaneMaskTable::PlaneMaskTable(int maskSide, int cubeSide)
    : maskSide_(maskSide),
      cubeSide_(cubeSide),
      words_(int((size_t(maskSide) * size_t(maskSide) + 63) / 64)) {
  VS_CHECK(maskSide >= 8 && maskSide <= 256 && maskSide % 8 == 0);
  VS_CHECK(cubeSide >= 1 && cubeSide <= 1024);
  const size_t cells = 3 * size_t(cubeSide) * size_t(cubeSide);  // faces +x, +y, +z
  bits_.assign(cells * size_t(words_), 0);
  disk_.assign(size_t(words_), 0);
  // The disk pixels and their hemisphere points, once.
  std::vector<glm::vec3> points;
  std::vector<uint32_t> index;
  for (int y = 0; y < maskSide; ++y)
    for (int x = 0; x < maskSide; ++x)
      if (maskPixelInDisk(maskSide, x, y)) {
        points.push_back(maskDirection(maskSide, x, y));
        index.push_back(uint32_t(y * maskSide + x));
        disk_[index.back() >> 6] |= uint64_t(1) << (index.back() & 63);
      }
  tbb::parallel_for(tbb::blocked_range<size_t>(0, cells, 256), [&](const auto& range) {
    for (size_t cell = range.begin(); cell != range.end(); ++cell) {
      const int face = 2 * int(cell / (size_t(cubeSide) * size_t(cubeSide)));
      const int rest = int(cell % (size_t(cubeSide) * size_t(cubeSide)));
      const glm::vec3 n = cellDirection(face, rest % cubeSide, rest / cubeSide, cubeSide);
      uint64_t* out = bits_.data() + cell * size_t(words_);
      for (size_t p = 0; p < points.size(); ++p)
        if (glm::dot(points[p], n) >= 0.0f) out[index[p] >> 6] |= uint64_t(1) << (index[p] & 63);
    }
  });
}

#if defined(__SSE2__)
namespace {

// The cube-map cells of the four normals in the lanes of (nx, ny, nz): per
// lane, cell (i, j) and flags (bit 0: a negative face; bits 1-2: the axis;
// all 0 for a normal with no major component, as cellOf's {0, 0, 0}). Every
// lookup goes through here (cellOf too), so scalar and batched lookups
// cannot disagree, whatever the compiler fuses. Selects, not branches:
// plane normals come in no order, so branching on the major axis
// mispredicts about half the time.
struct Cells4 {
  alignas(16) int32_t i[4], j[4], flags[4];
};
Cells4 cells4(int cubeSide, __m128 nx, __m128 ny, __m128 nz) {
  const __m128 signBit = _mm_set1_ps(-0.0f), zero = _mm_setzero_ps();
  const __m128 ax = _mm_andnot_ps(signBit, nx), ay = _mm_andnot_ps(signBit, ny),
               az = _mm_andnot_ps(signBit, nz);
  auto select = [](__m128 mask, __m128 a, __m128 b) {
    return _mm_or_ps(_mm_and_ps(mask, a), _mm_andnot_ps(mask, b));
  };
  const __m128 xMajor = _mm_and_ps(_mm_cmpge_ps(ax, ay), _mm_cmpge_ps(ax, az));
  const __m128 yMajor = _mm_andnot_ps(xMajor, _mm_cmpge_ps(ay, az));
  const __m128 xyMajor = _mm_or_ps(xMajor, yMajor);
  const __m128 m = select(xMajor, ax, select(yMajor, ay, az));
  const __m128 major = select(xMajor, nx, select(yMajor, ny, nz));
  const __m128 u = select(xMajor, ny, nx), v = select(xyMajor, nz, ny);
  const __m128 positive = _mm_cmpge_ps(major, zero);
  const __m128 valid = _mm_cmpgt_ps(m, zero);
  const float s = float(cubeSide);
  const __m128 half = _mm_set1_ps(0.5f * s), last = _mm_set1_ps(s - 1.0f);
  const __m128 scale = _mm_div_ps(half, m);
  // Clamped as floats before the conversion to int: max(t, 0) gives 0 for
  // NaN (from an infinite normal).
  auto cell = [&](__m128 c) {
    const __m128 t = _mm_add_ps(_mm_mul_ps(c, scale), half);
    return _mm_cvttps_epi32(_mm_and_ps(valid, _mm_min_ps(_mm_max_ps(t, zero), last)));
  };
  Cells4 out;
  _mm_store_si128(reinterpret_cast<__m128i*>(out.i), cell(u));
  _mm_store_si128(reinterpret_cast<__m128i*>(out.j), cell(v));
  const __m128i one = _mm_set1_epi32(1), two = _mm_set1_epi32(2), four = _mm_set1_epi32(4);
  const __m128i axis = _mm_or_si128(_mm_and_si128(_mm_castps_si128(yMajor), two),
                                    _mm_andnot_si128(_mm_castps_si128(xyMajor), four));
  const __m128i negative = _mm_andnot_si128(_mm_castps_si128(positive), one);
  _mm_store_si128(reinterpret_cast<__m128i*>(out.flags),
                  _mm_and_si128(_mm_castps_si128(valid), _mm_or_si128(axis, negative)));
  return out;
}

// above() for the four normals in the lanes; writes out[0..count) and
// prefetches each row.
void above4(const PlaneMaskTable& table, __m128 nx, __m128 ny, __m128 nz, int count,
            PlaneMaskTable::Mask* out) {
  const Cells4 c = cells4(table.cubeSide(), nx, ny, nz);
  const size_t side = size_t(table.cubeSide()), words = size_t(table.words());
  for (int k = 0; k < count; ++k) {
    // Cell (i, j) of a negative face holds the negated direction of cell
    // (side-1-i, side-1-j) of its positive face.
    const bool neg = c.flags[k] & 1;
    const size_t i = neg ? side - 1 - size_t(c.i[k]) : size_t(c.i[k]);
    const size_t j = neg ? side - 1 - size_t(c.j[k]) : size_t(c.j[k]);
    const size_t stored = (size_t(c.flags[k] >> 1) * side + j) * side + i;
    out[k] = {table.rows() + stored * words, neg ? ~uint64_t(0) : uint64_t(0)};
    const char* row = reinterpret_cast<const char*>(out[k].bits);
    for (size_t line = 0; line < words * sizeof(uint64_t); line += 64)
      __builtin_prefetch(row + line);
  }
}

}  // namespace
#endif

PlaneMaskTable::Cell PlaneMaskTable::cellOf(const glm::vec3& n) const {
#if defined(__SSE2__)
  const Cells4 c = cells4(cubeSide_, _mm_set1_ps(n.x), _mm_set1_ps(n.y), _mm_set1_ps(n.z));
  return {2 * (c.flags[0] >> 1) + (c.flags[0] & 1), c.i[0], c.j[0]};
#else
  const glm::vec3 a = glm::abs(n);
  int face;
  float u, v, m;
  if (a.x >= a.y && a.x >= a.z) {
    face = n.x >= 0.0f ? 0 : 1;
    u = n.y, v = n.z, m = a.x;
  } else if (a.y >= a.z) {
    face = n.y >= 0.0f ? 2 : 3;
    u = n.x, v = n.z, m = a.y;
  } else {
    face = n.z >= 0.0f ? 4 : 5;
    u = n.x, v = n.y, m = a.z;
  }
  if (!(m > 0.0f)) return {0, 0, 0};
  const float s = float(cubeSide_);
  const float scale = 0.5f * s / m;
  // Clamped as floats (NaN, from an infinite normal, gives 0) before the
  // conversion to int.
  auto cell = [&](float c) {
    return int(std::min(std::max(0.0f, c * scale + 0.5f * s), s - 1.0f));
  };
  return {face, cell(u), cell(v)};
#endif
}

PlaneMaskTable::Mask PlaneMaskTable::above(const glm::vec3& n) const {
  // Cell (i, j) of a negative face holds the negated direction of cell
  // (side-1-i, side-1-j) of its positive face.
  const Cell c = cellOf(n);
  const size_t side = size_t(cubeSide_);
  const bool negative = c.face & 1;
  const size_t i = negative ? side - 1 - size_t(c.i) : size_t(c.i);
  const size_t j = negative ? side - 1 - size_t(c.j) : size_t(c.j);
  const size_t stored = (size_t(c.face >> 1) * side + j) * side + i;
  return {bits_.data() + stored * size_t(words_), negative ? ~uint64_t(0) : uint64_t(0)};
}

void PlaneMaskTable::aboveAll(const glm::vec3 normals[4], int count, Mask out[4]) const {
  VS_DCHECK(count >= 0 && count <= 4);
  if (count == 0) return;
#if defined(__SSE2__)
  glm::vec3 n[4] = {};
  for (int k = 0; k < count; ++k) n[k] = normals[k];
  above4(*this, _mm_set_ps(n[3].x, n[2].x, n[1].x, n[0].x),
         _mm_set_ps(n[3].y, n[2].y, n[1].y, n[0].y), _mm_set_ps(n[3].z, n[2].z, n[1].z, n[0].z),
         count, out);
#else
  for (int k = 0; k < count; ++k) out[k] = above(normals[k]);
#endif
}

void PlaneMaskTable::aboveMany(const float* x, const float* y, const float* z, size_t n,
                               Mask* out) const {
#if defined(__SSE2__)
  size_t k = 0;
  for (; k + 4 <= n; k += 4)
    above4(*this, _mm_loadu_ps(x + k), _mm_loadu_ps(y + k), _mm_loadu_ps(z + k), 4, out + k);
  if (k < n) {
    float tx[4] = {}, ty[4] = {}, tz[4] = {};
    for (size_t r = k; r < n; ++r) tx[r - k] = x[r], ty[r - k] = y[r], tz[r - k] = z[r];
    above4(*this, _mm_loadu_ps(tx), _mm_loadu_ps(ty), _mm_loadu_ps(tz), int(n - k), out + k);
  }
#else
  for (size_t k = 0; k < n; ++k) out[k] = above({x[k], y[k], z[k]});
#endif
}

glm::vec3 PlaneMaskTable::quantized(const glm::vec3& n) const {
  const Cell c = cellOf(n);
  return cellDirection(c.face, c.i, c.j, cubeSide_);
}

namespace {

// The edge planes of blocker (a, b, c) clipped to the upper half-space,
// oriented so the cone's inside is on their positive side: 3 or 4 of them, or
// 0 where the blocker draws nothing (edge-on to the vertex, or not above the
// tangent plane).
int edgePlanes(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, glm::vec3 planes[4]) {
  // Edge-on to the vertex: the triangle's plane passes through the origin.
  // |triple| > 1e-6 |a| |b| |c|, squared (in double: the product of six
  // squared lengths leaves float's range for huge triangles).
  const float triple = glm::dot(a, glm::cross(b, c));
  const double scale2 = double(glm::dot(a, a)) * double(glm::dot(b, b)) * double(glm::dot(c, c));
  if (!(double(triple) * double(triple) > 1e-12 * scale2)) return 0;
  if (!(std::max({a.z, b.z, c.z}) > 0.0f)) return 0;
  const float sign = triple > 0.0f ? 1.0f : -1.0f;
  if (std::min({a.z, b.z, c.z}) >= 0.0f) {  // wholly above: no clipping (most blockers)
    planes[0] = sign * glm::cross(a, b);
    planes[1] = sign * glm::cross(b, c);
    planes[2] = sign * glm::cross(c, a);
    return 3;
  }
  const glm::vec3 in[3] = {a, b, c};
  glm::vec3 poly[4];
  const int n = clipToUpperHalf(in, poly);
  if (n < 3) return 0;
  for (int k = 0; k < n; ++k) planes[k] = sign * glm::cross(poly[k], poly[(k + 1) % n]);
  return n;
}

}  // namespace

namespace {

// ORs the blocker of edge-plane masks m[0..count) into out.
void drawPlanes(const PlaneMaskTable::Mask* m, int count, const uint64_t* disk, int words,
                uint64_t* out) {
  if (count == 3)
    for (int w = 0; w < words; ++w)
      out[w] |= (m[0].bits[w] ^ m[0].flip) & (m[1].bits[w] ^ m[1].flip) &
                (m[2].bits[w] ^ m[2].flip) & disk[w];
  else if (count == 4)
    for (int w = 0; w < words; ++w)
      out[w] |= (m[0].bits[w] ^ m[0].flip) & (m[1].bits[w] ^ m[1].flip) &
                (m[2].bits[w] ^ m[2].flip) & (m[3].bits[w] ^ m[3].flip) & disk[w];
}

}  // namespace

void BlockerBatch::clear() {
  x_.clear();
  y_.clear();
  z_.clear();
  counts_.clear();
}

bool BlockerBatch::add(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
  glm::vec3 planes[4];
  const int count = edgePlanes(a, b, c, planes);
  if (count == 0) return false;
  for (int k = 0; k < count; ++k) {
    x_.push_back(planes[k].x);
    y_.push_back(planes[k].y);
    z_.push_back(planes[k].z);
  }
  counts_.push_back(uint8_t(count));
  return true;
}

void BlockerBatch::draw(const PlaneMaskTable& table, VisibilityMask& mask) {
  VS_CHECK_EQ(table.maskSide(), mask.side());
  masks_.resize(x_.size());
  table.aboveMany(x_.data(), y_.data(), z_.data(), x_.size(), masks_.data());
  const PlaneMaskTable::Mask* m = masks_.data();
  for (const uint8_t count : counts_) {
    drawPlanes(m, count, table.disk(), mask.words(), mask.data());
    m += count;
  }
}

bool rasterizeBlocker(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                      const PlaneMaskTable* table, VisibilityMask& mask) {
  glm::vec3 planes[4];
  const int n = edgePlanes(a, b, c, planes);
  if (n == 0) return false;
  if (table) {
    VS_CHECK_EQ(table->maskSide(), mask.side());
    PlaneMaskTable::Mask masks[4];
    table->aboveAll(planes, n, masks);
    drawPlanes(masks, n, table->disk(), mask.words(), mask.data());
    return true;
  }
  const int side = mask.side();
  for (int y = 0; y < side; ++y)
    for (int x = 0; x < side; ++x) {
      if (!maskPixelInDisk(side, x, y)) continue;
      const glm::vec3 s = maskDirection(side, x, y);
      bool inside = true;
      for (int k = 0; k < n && inside; ++k) inside = glm::dot(s, planes[k]) >= 0.0f;
      if (inside) mask.set(x, y);
    }
  return true;
}

}  // namespace vistream
