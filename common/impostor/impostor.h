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
//    one texel, used from everywhere;
//  - its precision: points on the cell's perspective grid (PointGrid,
//    below: equal steps of angle and of inverse depth), the texels of textured points multiples of
//    colourStep levels (single colours stay exact: they are most of the points and carry the
//    facades' flat colours, where a step would show). The bake snaps both
//    (quantize), so the encoding (protocol/impostor) gives back exactly the
//    impostor the bake measured.
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
#include <optional>
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

// Where an impostor's points may lie: a perspective grid seen from the
// cell's centre c, along the sampling plane's normal n with e1 the plane's u
// axis made orthogonal to n and e2 = n x e1. A point p = c + z (n + x e1 +
// y e2) has coordinates (x, y, ln z), each on equal steps from its least
// value over the box's corners (the box lies in front of c, so each range
// holds the whole box). Equal steps of angle keep a point's displacement on
// the screen the same at any depth. Equal steps of log depth keep its
// relative depth error the same (what ordering the impostor's own surfaces
// in the z-buffer asks for), and its parallax error for a viewer within r of
// c falls with depth: with angle step a and log-depth step g, such a viewer
// sees a point moved by at most a / 2 + r g / (2 z) radians (to first order
// in r / z and g). A baked box's depth range is narrow in log depth, so
// depth takes a fraction of the bits a Cartesian grid would.
struct PointGrid {
  static constexpr uint32_t kMaxBits = 21;    // per axis: a 63-bit Morton code
  static constexpr float kMaxTangent = 8.0f;  // of the box's corners, off the normal
  glm::vec3 centre{0.0f}, normal{0.0f}, e1{0.0f}, e2{0.0f};
  glm::vec3 lo{0.0f}, step{0.0f};   // (x, y, ln z)
  std::array<uint32_t, 3> steps{};  // the highest coordinate per axis
  float slack = 0.0f;  // metres: how far a grid point may lie from the box's point it stands for

  // The grid of a box seen from a cell through a sampling plane, with the
  // given steps (0: 16 bits over the box's range on that axis); nothing
  // when the box does not lie wholly in front of the cell's centre along the
  // plane's normal within kMaxTangent, the plane's axes are degenerate, or
  // the steps or reach lie beyond float.
  static std::optional<PointGrid> of(const Box3f& cell, const Box3f& box,
                                     const SamplingPlane& plane, float angleStep,
                                     float logDepthStep);

  // Coordinates of a point (clamped into the grid's range) and back.
  std::array<uint32_t, 3> coordinates(const glm::vec3& p) const;
  glm::vec3 point(const std::array<uint32_t, 3>& q) const;
};

struct Impostor {
  Box3f cell, box;
  SamplingPlane plane;
  std::array<glm::vec3, 3> cameras{};  // the LDI cameras (corners of the triangle round the shaft)
  uint32_t textureWidth = 8, textureHeight = 2;
  // Precision (see above): the perspective grid's steps (0: 16 bits per
  // axis over the box's range) and the textures' colour step, 1, 2, 4, 8 or
  // 16 (8-bit levels).
  float angleStep = 0.0f;     // tangent units
  float logDepthStep = 0.0f;  // natural log of metres
  uint32_t colourStep = 1;

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
  // The grid its points lie on (PointGrid::of its cell, box, plane and
  // steps); never nothing for a baked impostor: the bake refuses a box
  // without a grid before sampling it.
  std::optional<PointGrid> pointGrid() const;
  // Snaps every point to the grid and every texel of a textured point to a
  // multiple of colourStep (the top step clamped to 255). Idempotent.
  void quantize();
  // A colour level snapped to `step` levels: min(255, round(v / step) step),
  // that is levelOf(levelIndex(v, step), step) (the codec stores the index).
  static uint8_t snapLevel(uint8_t v, uint32_t step);
  // Whether `step` is a colour step the encoding has a code for: 1, 2, 4, 8
  // or 16.
  static bool isColourStep(uint32_t step) {
    return step != 0 && step <= 16 && !(step & (step - 1));
  }
  static uint8_t levelIndex(uint8_t v, uint32_t step);
  static uint8_t levelOf(uint32_t index, uint32_t step);
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
