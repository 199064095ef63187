// Point-based impostors (Wimmer 2001, chapter 5): the far field of one view
// cell, in one box, as z-buffered points whose colour depends on where in the
// cell the viewer stands.
//
// An Impostor is what the bake (server/impostor/impostor_bake.h) produces and
// every renderer draws:
//  - the view cell and the impostor's box (local frame, metres);
//  - the sampling plane: a rectangle facing from the cell towards the box,
//    at the cell's far side, through which every ray from the cell to the box
//    passes. It parameterizes viewer positions: a viewer at `eye` looking at
//    point p is at the rectangle coordinates where the line from eye to p
//    crosses the plane (textureCoordinates), the thesis's off-axis frustum
//    of Figure 5.10;
//  - per point, its position and a small texture over that rectangle
//    (textureWidth x textureHeight texels, 8x2 in the thesis; texel (i, j)
//    has its centre at ((i + 0.5) / width, (j + 0.5) / height)). A point's
//    colour seen from `eye` is its texture at the eye's coordinates, bilinear
//    between texel centres and clamped at the edges (colourSeenFrom);
//  - compression (section 5.4.3): a point whose texture varies little keeps
//    one texel, used from everywhere.
// Colours are the ones the client shows (8-bit, the scene's baked lighting
// with the haze of their distance from the sampling plane already applied),
// so a renderer draws them as they are.
//
// Drawing (every renderer the same): each point is projected with the
// viewer's camera and covers the pixel centres within a splat radius of its
// projection, z-buffered (PointSplat in client/render/impostor_splat.h). The
// bake's sampling density keeps neighbouring points less than a pixel apart,
// so the splat leaves no hole (tests/server/impostor: 0 uncovered pixels).
//
// Thread safety: immutable after the bake; lookups are const.
#pragma once

#include <array>
#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "common/core/box.h"

namespace vistream {

struct SamplingPlane {
  glm::vec3 origin{0.0f};               // the rectangle's corner at coordinates (0, 0)
  glm::vec3 uAxis{1.0f, 0.0f, 0.0f};    // edge from (0, 0) to (1, 0): horizontal
  glm::vec3 vAxis{0.0f, 1.0f, 0.0f};    // edge from (0, 0) to (0, 1): upwards in the plane
  glm::vec3 normal{0.0f, 0.0f, -1.0f};  // unit, from the cell towards the box

  // Coordinates of the point where the line through `eye` and `p` crosses
  // the plane, in units of the rectangle ((0, 0) to (1, 1) inside it), or
  // the eye's own coordinates when the line runs parallel to the plane.
  glm::vec2 textureCoordinates(const glm::vec3& eye, const glm::vec3& p) const;
  // The point at rectangle coordinates (s, t).
  glm::vec3 at(float s, float t) const { return origin + s * uAxis + t * vAxis; }
};

struct Impostor {
  Box3f cell, box;
  SamplingPlane plane;
  std::array<glm::vec3, 3> cameras{};  // the LDI cameras (corners of the triangle round the shaft)
  uint32_t textureWidth = 8, textureHeight = 2;

  std::vector<glm::vec3> points;  // local frame
  // Per point: its first texel in `texels`, which holds textureTexels()
  // texels row by row, or one for a single-colour point.
  std::vector<uint32_t> firstTexel;
  std::vector<uint8_t> singleColour;  // per point: 1 if it keeps one texel
  std::vector<glm::u8vec3> texels;
  // The bounds of each run of kBlockPoints consecutive points (the last run
  // may be shorter), for a renderer to skip runs wholly out of view or
  // wholly behind nearer geometry; filled by boundBlocks() (the bake and the
  // decoder call it). Not part of the wire format or bytes(). A count that
  // does not match the points means "not computed": renderers then draw
  // every point.
  static constexpr size_t kBlockPoints = 256;
  std::vector<Box3f> blockBounds;

  size_t size() const { return points.size(); }
  size_t blockCount() const { return (points.size() + kBlockPoints - 1) / kBlockPoints; }
  bool hasBlockBounds() const { return blockBounds.size() == blockCount(); }
  void boundBlocks();
  uint32_t textureTexels() const { return textureWidth * textureHeight; }
  // The colour of point k seen from `eye` (0..255 per channel, unrounded).
  glm::vec3 colourSeenFrom(size_t k, const glm::vec3& eye) const;
  // The same at rectangle coordinates st (textureCoordinates of the eye).
  glm::vec3 colourAt(size_t k, const glm::vec2& st) const;
  // Bytes of the representation: 12 a point, 4 for its texel offset and
  // flag, 3 a texel (what a stream or a file of it holds, headers aside).
  size_t bytes() const;
  // The same if every point kept its whole texture (no compression).
  size_t bytesUncompressed() const;
  // Appends a point with a whole texture (textureTexels() colours) or, when
  // `single`, with the first of them only.
  void appendPoint(const glm::vec3& p, const glm::u8vec3* colours, bool single);
};

}  // namespace vistream
