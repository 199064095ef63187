#include "common/avatar/hemisphere_raster.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>

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

PlaneMaskTable::Cell PlaneMaskTable::cellOf(const glm::vec3& n) const {
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
  const float triple = glm::dot(a, glm::cross(b, c));
  const float scale = glm::length(a) * glm::length(b) * glm::length(c);
  if (!(std::abs(triple) > 1e-6f * scale)) return 0;
  if (!(std::max({a.z, b.z, c.z}) > 0.0f)) return 0;
  const glm::vec3 in[3] = {a, b, c};
  glm::vec3 poly[4];
  const int n = clipToUpperHalf(in, poly);
  if (n < 3) return 0;
  const float sign = triple > 0.0f ? 1.0f : -1.0f;
  for (int k = 0; k < n; ++k) planes[k] = sign * glm::cross(poly[k], poly[(k + 1) % n]);
  return n;
}

}  // namespace

bool lookUpBlocker(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                   const PlaneMaskTable& table, TableBlocker& out) {
  glm::vec3 planes[4];
  out.count = edgePlanes(a, b, c, planes);
  const size_t bytes = size_t(table.words()) * sizeof(uint64_t);
  for (int k = 0; k < out.count; ++k) {
    out.planes[k] = table.above(planes[k]);
    const char* row = reinterpret_cast<const char*>(out.planes[k].bits);
    for (size_t line = 0; line < bytes; line += 64) __builtin_prefetch(row + line);
  }
  return out.count > 0;
}

void drawBlocker(const TableBlocker& blocker, const PlaneMaskTable& table, VisibilityMask& mask) {
  VS_CHECK_EQ(table.maskSide(), mask.side());
  const int words = mask.words();
  const PlaneMaskTable::Mask* m = blocker.planes;
  const uint64_t* disk = table.disk();
  uint64_t* out = mask.data();
  if (blocker.count == 3)
    for (int w = 0; w < words; ++w)
      out[w] |= (m[0].bits[w] ^ m[0].flip) & (m[1].bits[w] ^ m[1].flip) &
                (m[2].bits[w] ^ m[2].flip) & disk[w];
  else if (blocker.count == 4)
    for (int w = 0; w < words; ++w)
      out[w] |= (m[0].bits[w] ^ m[0].flip) & (m[1].bits[w] ^ m[1].flip) &
                (m[2].bits[w] ^ m[2].flip) & (m[3].bits[w] ^ m[3].flip) & disk[w];
}

bool rasterizeBlocker(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                      const PlaneMaskTable* table, VisibilityMask& mask) {
  if (table) {
    TableBlocker blocker;
    if (!lookUpBlocker(a, b, c, *table, blocker)) return false;
    drawBlocker(blocker, *table, mask);
    return true;
  }
  glm::vec3 planes[4];
  const int n = edgePlanes(a, b, c, planes);
  if (n == 0) return false;
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
