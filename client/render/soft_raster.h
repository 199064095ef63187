// A software triangle rasterizer for the client: the headless near field
// (colour via triangle IDs, with a depth test) and the opacity buffer (which
// pixels the near field covers, no depth, no shading), as in the thesis's
// section 4.6, where a fast software renderer makes the opacity buffer so
// nothing is read back from the GPU.
//
// Rules (chosen to match OpenGL's rasterization of the same triangles):
//  - a pixel is drawn when its centre lies inside the triangle; vertices are
//    snapped to 1/256 pixel and edge functions are exact integers, with the
//    top-left rule for centres exactly on an edge, so two triangles sharing an
//    edge never both draw, or both miss, a pixel on it;
//  - triangles are clipped against the near plane and a guard band in
//    homogeneous clip space; both windings are drawn (two-sided);
//  - depth is 1/w, the inverse view depth, interpolated linearly in screen
//    space (it orders fragments exactly as OpenGL's NDC z); the larger wins,
//    and of equal depths the triangle earlier in `which` (as OpenGL's LESS
//    test keeps the first drawn);
//  - draw() visits triangles nearest first and skips a triangle in a band of
//    rows where every pixel it could reach already holds something nearer
//    than its nearest vertex: the result is the same as drawing all of them
//    in `which` order, for less work when the scene hides much of itself;
//  - vertices are transformed relative to the eye (Camera::rotationProjection);
//  - a maximum distance along the view ray (the near-field distance d) drops
//    fragments beyond it, as the OpenGL near field's fragment shader does.
// Coverage with an inset counts a pixel only if its centre lies at least
// `insetPx` inside every edge: a subset of what OpenGL draws, so a pixel the
// opacity buffer calls covered is never left empty by the GPU.
//
// Thread safety: an instance is used by one thread at a time; it runs its own
// work on TBB internally.
#pragma once

#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "client/render/camera.h"
#include "common/scene/scene.h"

namespace vistream {

inline constexpr uint32_t kNoTriangle = 0xffffffffu;
// A pixel whose nearest fragment lies beyond the maximum distance.
inline constexpr uint32_t kBeyondDistance = 0xfffffffeu;

// What the opacity buffer says of a pixel.
enum Coverage : uint8_t {
  kUncovered = 0,  // no polygon at all (not even beyond the maximum distance)
  kCovered = 1,    // a polygon within the maximum distance
  kBeyond = 2,  // polygons, but the nearest lies beyond the maximum distance (or it is undecided)
};

struct IdBuffer {
  int width = 0, height = 0;
  std::vector<uint32_t>
      ids;  // per pixel, row 0 at the top: triangle index, kNoTriangle or kBeyondDistance
  std::vector<float> inverseDepth;  // per pixel, 1 / view depth (1/metres along the view axis); 0
                                    // where nothing was drawn

  void reset(int w, int h);
  uint32_t at(int x, int y) const { return ids[size_t(y) * size_t(width) + size_t(x)]; }
};

// The opacity buffer of an id buffer, one Coverage a pixel: kUncovered for
// kNoTriangle, kBeyond for kBeyondDistance, kCovered for a triangle
// (in parallel).
void coverageOf(const IdBuffer& ids, std::vector<uint8_t>& covered);

struct RasterStats {
  size_t trianglesIn = 0;     // triangles handed in
  size_t trianglesSetUp = 0;  // after clipping and culling (a clipped triangle may count twice)
  // Set-up triangles skipped in a band of rows because everything the band
  // already held there was nearer (hierarchical depth; draw(), and coverage()
  // with an inset of 0 or more).
  size_t bandsSkipped = 0;
};

class SoftwareRasterizer {
 public:
  // Draws `which` (indices into `triangles`) into `out` with a depth test,
  // after clearing it to the camera's size. Pixels whose nearest fragment lies
  // farther than maxDistance from the eye (along the pixel's ray) get
  // kBeyondDistance.
  RasterStats draw(const Camera& camera, const FlatTriangles& triangles,
                   std::span<const uint32_t> which, IdBuffer& out,
                   float maxDistance = std::numeric_limits<float>::infinity());
  // The opacity buffer for an OpenGL near field, one Coverage a pixel:
  // kCovered where the pixel centre lies at least insetPx inside a triangle
  // whose fragment there is at most maxDistance * (1 - 1e-4) from the eye (a
  // subset of what OpenGL draws with the same maximum distance); kUncovered
  // where no triangle grown by insetPx reaches the centre (a subset of what
  // OpenGL leaves empty; the growth is mitred, cut at 8 insetPx at corners
  // sharper than 15 degrees); kBeyond for the rest.
  RasterStats coverage(const Camera& camera, const FlatTriangles& triangles,
                       std::span<const uint32_t> which, float insetPx,
                       std::vector<uint8_t>& covered,
                       float maxDistance = std::numeric_limits<float>::infinity());

 private:
  struct ScreenTriangle {
    int64_t x[3], y[3];  // 1/256 pixel, y down
    float invW[3];       // 1 / view depth
    uint32_t id;
    int minX, maxX, minY, maxY;  // pixel bounds, clamped to the image
  };
  void setUp(const Camera& camera, const FlatTriangles& triangles, std::span<const uint32_t> which);
  // Fills `out` with the set-up triangles; returns the number of (triangle,
  // band) pairs skipped as hidden.
  size_t fill(const Camera& camera, float insetPx, IdBuffer& out);
  // Clears pixels whose fragment lies beyond maxDistance along the pixel ray.
  static void dropBeyond(const Camera& camera, float maxDistance, IdBuffer& out);
  std::vector<ScreenTriangle> screen_;
  std::vector<uint32_t> order_;  // the order fill() draws screen_ in
  std::vector<uint32_t> owner_;  // per pixel: the screen_ index drawn there (ties go to the lower)
  IdBuffer scratch_;
};

}  // namespace vistream
