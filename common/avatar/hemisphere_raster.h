// Hemispherical rasterization of blocker triangles into 1-bit visibility
// masks (Kautz, Lehtinen and Aila 2004, section 3.1).
//
// A vertex's visibility mask is a side x side grid of bits over the unit
// disk in its tangent frame (normal +z): pixel (x, y) stands for the point of
// the upper hemisphere above its centre, (dx, dy, sqrt(1 - dx^2 - dy^2)).
// Dropping z is the Nusselt analog: equal areas of the disk are equal
// projected solid angles, so the mask samples the hemisphere by cosine
// importance. Pixels whose centre lies outside the disk are never set.
//
// A blocker triangle, given relative to the vertex in its tangent frame, is
// clipped to the upper half-space; each edge of what remains spans a plane
// with the origin, and a pixel is covered when its hemisphere point lies on
// the inner side of every edge plane. The masks of "the pixels above a
// plane" come from a table indexed by the plane's normal on a cube map
// (6 x cube x cube cells, each holding the mask of its centre direction's
// plane), so a triangle costs three or four lookups and a bitwise AND of
// side * side / 64 words; blockers are ORed together (occluder fusion). A
// null table tests the exact planes instead (the reference, and the knob
// "plane table off"). Only the three positive faces of the cube map are
// stored: the pixels above the plane of -n are the disk's pixels not above
// the plane of n (the two differ only on the plane itself, a set of measure
// zero), so a normal on a negative face reads its mirror cell complemented.
// Half the table is half the cache misses, and those are most of what a
// triangle costs.
//
// Hard cases: a triangle whose plane passes through the vertex (it contains
// the vertex, or the vertex lies on one of its edges or their lines) covers
// no solid angle and draws nothing; a triangle wholly at or below the
// tangent plane draws nothing; huge triangles are only directions and need
// no special care.
//
// Thread safety: a PlaneMaskTable is immutable once built; masks are the
// caller's.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

namespace vistream {

class VisibilityMask {
 public:
  explicit VisibilityMask(int side = 32);  // side: a multiple of 8, 8..256

  int side() const { return side_; }
  int words() const { return int(bits_.size()); }
  void clear();
  bool test(int x, int y) const {
    const size_t i = size_t(y) * size_t(side_) + size_t(x);
    return (bits_[i >> 6] >> (i & 63)) & 1u;
  }
  void set(int x, int y) {
    const size_t i = size_t(y) * size_t(side_) + size_t(x);
    bits_[i >> 6] |= uint64_t(1) << (i & 63);
  }
  size_t count() const;  // set bits
  uint64_t* data() { return bits_.data(); }
  const uint64_t* data() const { return bits_.data(); }

 private:
  int side_;
  std::vector<uint64_t> bits_;
};

// Whether pixel (x, y) of a side x side mask has its centre inside the disk,
// and the hemisphere point above that centre (z = 0 outside the disk).
bool maskPixelInDisk(int side, int x, int y);
glm::vec3 maskDirection(int side, int x, int y);

class PlaneMaskTable {
 public:
  // Masks of `maskSide` for the 6 * cubeSide^2 plane normals at the centres
  // of a cube map's cells (cubeSide >= 1), of which the 3 * cubeSide^2 on
  // positive faces are stored. 32 and 128 (the paper's) take 6 MiB and about
  // 0.05 s to build on two cores.
  PlaneMaskTable(int maskSide, int cubeSide);

  int maskSide() const { return maskSide_; }
  int cubeSide() const { return cubeSide_; }
  int words() const { return words_; }
  size_t bytes() const { return bits_.size() * sizeof(uint64_t); }
  // The disk pixels whose hemisphere point s has s . n >= 0, for the table's
  // normal nearest `n` (any length; zero gives the +x face's): word w is
  // (bits[w] ^ flip) & disk()[w].
  struct Mask {
    const uint64_t* bits;
    uint64_t flip;  // 0, or all ones for a normal on a negative face
  };
  Mask above(const glm::vec3& n) const;
  // above() of normals[0..count), count <= 4, at once: the same masks, found
  // with four-wide selects instead of branches (a blocker's three or four
  // edge planes come in no order, so the branches of the scalar face choice
  // mispredict about half the time).
  void aboveAll(const glm::vec3 normals[4], int count, Mask out[4]) const;
  // above() of the n normals (x[k], y[k], z[k]), four at a time; each found
  // row is prefetched.
  void aboveMany(const float* x, const float* y, const float* z, size_t n, Mask* out) const;
  // The pixels inside the disk.
  const uint64_t* disk() const { return disk_.data(); }
  // The stored rows: words() words for each cell of the +x, +y, +z faces.
  const uint64_t* rows() const { return bits_.data(); }
  // The unit normal of the cell `n` falls in (on a negative face, the
  // mirror of the stored cell's).
  glm::vec3 quantized(const glm::vec3& n) const;

 private:
  struct Cell {
    int face, i, j;  // face 0..5: +x, -x, +y, -y, +z, -z
  };
  Cell cellOf(const glm::vec3& n) const;

  int maskSide_, cubeSide_, words_;
  std::vector<uint64_t> bits_;  // words_ per cell of the positive faces
  std::vector<uint64_t> disk_;  // words_
};

// ORs blocker triangle (a, b, c) into `mask`: positions relative to the
// receiving vertex, in its tangent frame. With a null table the edge planes
// are tested exactly per pixel (slow). Returns whether the triangle reached
// the rasterizer (above the tangent plane, not edge-on to the vertex).
bool rasterizeBlocker(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                      const PlaneMaskTable* table, VisibilityMask& mask);

// rasterizeBlocker with a table for many blockers of one vertex: add() each
// (it finds the edge planes), then draw() looks all the planes up, four at a
// time, prefetching each table row as soon as it is known, and ORs the
// blockers into the mask after, so that the cache misses of many blockers
// overlap instead of stalling one by one. The mask is bit for bit the one
// rasterizeBlocker would draw. Reusable: clear() keeps the storage.
class BlockerBatch {
 public:
  void clear();
  // False (and nothing added) where rasterizeBlocker would return false.
  bool add(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c);
  size_t size() const { return counts_.size(); }
  void draw(const PlaneMaskTable& table, VisibilityMask& mask);

 private:
  std::vector<float> x_, y_, z_;  // edge-plane normals, 3 or 4 a blocker
  std::vector<uint8_t> counts_;   // per blocker
  std::vector<PlaneMaskTable::Mask> masks_;
};

}  // namespace vistream
