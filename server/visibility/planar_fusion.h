// Occluder fusion within a plane: walls made of many solid pieces (wall
// patches, a wall with a door and its lintel, abutting buildings) hide
// together what no single piece hides. A stage of the single-occluder PVS
// (epsilon_pvs.h), for interiors above all, where the 2.5D horizons
// (horizon_fusion.h) do not apply. The idea is the planar case of the
// extended projections of Durand, Drettakis, Thollot and Puech, "Conservative
// Visibility Preprocessing using Extended Projections" (SIGGRAPH 2000): the
// occluders are fused on a projection plane, where a convex footprint that
// their union covers proves the occludee hidden.
//
// Proof of conservativeness. Take a plane P (unit normal n) that some
// faces of solid occluders lie in (ConvexOccluder::Kind::Solid, a convex
// region R_i inside the closed geometry: occluders.h), and a thin slab S
// just behind it, between the parallel planes at heights top and
// bottom = top - e (heights measured along n), at least e behind every such
// face. For each such solid, Q_i is the set of points x of the plane at
// height top whose whole segment across S (x, x - e n) lies in R_i: a
// convex polygon, R_i's half-spaces evaluated at both ends. The prism
// Q_i x [bottom, top] then lies in R_i. Let a view cell A lie strictly in
// front of S (every point above top) and an occludee face B strictly behind
// it (every point below bottom). Every segment from a point of A to a point
// of B crosses S from top to bottom; its part inside S projects (along n)
// into F, the convex hull of the projections of conv(A u B) n S, which is
// the convex hull of the intersections of the segments between the
// corners of A and the vertices of B with the two planes of S (the edges
// of conv(A u B) that cross S join a corner of A to a vertex of B). If F
// lies in the union of the Q_i, the segment's part inside S (of positive
// length) lies in the union of the prisms, so a piece of it of positive
// length lies in one prism, inside R_i: the segment enters the solid,
// unless it only grazes the prism's side (a measure-zero set of lines in a
// side face's plane). B is hidden from every point of A.
//
// Numerics: F is computed in double from float inputs; pieces of F left
// uncovered that are narrower than a few rounding margins
// (occluderMargin(), the amount solid occluders are shrunk by) count as
// covered: they are the seams the shrinking opens between abutting solids,
// or lines grazing a solid's edge within rounding. Occluders of the polygon
// kind (zero thickness) take no part.
//
// Cost: per cell, the planes with the cell in front; per face, those of
// them whose occluders' bounds meet the face's shaft and that have the face
// behind. Thread safety: hidden() is const and may run concurrently, each
// thread with its own CellPlanes.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <span>
#include <vector>

#include "common/core/box.h"
#include "common/spatial/xz_grid.h"
#include "server/visibility/occluders.h"

namespace vistream {

class PlanarFusion {
 public:
  // Groups the faces of the solid occluders by plane. `occluders` need not
  // outlive this object.
  explicit PlanarFusion(const OccluderSet& occluders);

  // The planes worth trying for a cell (those with the cell in front),
  // computed once per cell. hidden() keeps in it, for each cell of the
  // pieces' grid it has read, the planes in front that the grid cell lists
  // (each once), so that later faces of the same view cell read those short
  // lists instead of every piece (on bigcity, with 2 m grid cells, a cell
  // listed about 23 pieces, 7 of them of planes in front). One CellPlanes
  // serves one thread.
  struct CellPlanes {
    std::vector<uint8_t> inFront;  // by plane
    size_t count = 0;              // planes in front
    bool empty() const { return count == 0; }
    // Per grid cell: 0 until read, then 1 + its index in `ranges`, the range
    // of `lists` holding its planes in front.
    std::vector<uint32_t> slot;
    std::vector<std::pair<uint32_t, uint32_t>> ranges;
    std::vector<uint32_t> lists;
  };
  CellPlanes planesFor(const Box3f& cell) const;

  // True if the occluders of one plane together hide the convex hull of
  // `vertices` (an occludee face, local frame) from every point of `cell`.
  // Only planes met by the X/Z segment from the cell's centre to the first
  // vertex are tried (the line along it must cross a piece), found by
  // walking the pieces' X/Z grid along it: the cost follows the segment's
  // length, not the number of planes (bigcity has tens of thousands).
  bool hidden(const Box3f& cell, CellPlanes& planes, std::span<const glm::dvec3> vertices) const;

  size_t planeCount() const { return planes_.size(); }

 private:
  struct Plane {
    glm::dvec3 n{0.0}, u{0.0}, v{0.0};            // unit normal and an in-plane basis
    double top = 0.0, bottom = 0.0;               // the slab S along n
    Box3f bounds;                                 // of the member polygons (at height top)
    std::vector<std::vector<glm::dvec2>> pieces;  // the Q_i, counter-clockwise in (u, v)
    std::vector<glm::dvec4> pieceBounds;          // (min u, min v, max u, max v), by min u
    double widest = 0.0;                          // largest u extent of a piece
    double margin = 0.0;                          // rounding margin of its coordinates
  };
  std::vector<Plane> planes_;
  XzGrid grid_;                       // pieces by X/Z cell of their bounds (grown by the slack)
  std::vector<uint32_t> pieceOwner_;  // a grid item's plane
};

}  // namespace vistream
