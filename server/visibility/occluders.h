// Convex occluders for the conservative epsilon-neighbourhood PVS
// (Cohen-Or and Zadicario 1998, section 3: "the occluders are convex objects").
//
// Two kinds, both stored as a convex region that lies certainly inside the
// geometry it stands for, so that "a line crosses the occluder" implies "the
// line is blocked by scene geometry":
//  - Solid: a closed, consistently oriented, convex connected component of an
//    object (a building block, a box of furniture). Its region is the
//    intersection of one half-space per face plane, each pushed inward past
//    the face's innermost vertex and by a rounding margin. Such a region
//    crosses no boundary triangle and contains the component's centroid, so it
//    lies inside the solid even when float noise bends the faces.
//  - Polygon: a convex planar polygon formed by coplanar triangles of one
//    object that share edges (walls, floors, roofs), or one face or triangle
//    when their union is not convex. A line is blocked when it crosses the
//    polygon's plane strictly inside the polygon shrunk by the margin (and by
//    the depth of any float-noise notch in its outline).
// Degenerate triangles never contribute to an occluder. Dynamic objects are
// never occluders.
//
// All geometry is in the scene's local frame, in double precision.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "common/core/box.h"
#include "common/scene/scene.h"

namespace vistream {

struct ConvexOccluder {
  enum class Kind : uint8_t { Solid, Polygon };
  Kind kind = Kind::Solid;
  uint32_t object = 0;  // index into Scene::objects
  // Solid: half-spaces dot(n, x) < d (outward n, unit length), already shrunk.
  // Polygon: the edge half-spaces within the polygon plane, already shrunk,
  // then one last entry (n, h): the slab of half-thickness h around the
  // supporting plane that holds every vertex (float noise).
  std::vector<glm::dvec4> planes;  // (n.x, n.y, n.z, d)
  glm::dvec4 plane{0.0};           // Polygon only: supporting plane (unit n, d)
  Box3f bounds;                    // of the occluder region (for the acceleration structure)
  double area = 0.0;               // surface area (solid) or polygon area, m^2
  glm::dvec3 centre{0.0};
};

struct OccluderExtractionStats {
  size_t solids = 0;
  size_t polygons = 0;
  size_t mergedPolygons = 0;   // polygons made of more than one triangle
  size_t nonConvexGroups = 0;  // coplanar groups split back into faces or triangles
  double timeMs = 0.0;
};

struct OccluderSet {
  std::vector<ConvexOccluder> occluders;
  OccluderExtractionStats stats;
};

struct OccluderOptions {
  bool solids = true;    // closed convex components as solid occluders
  bool polygons = true;  // convex planar polygons
  // Occluders smaller than this across (solids: longest box side; polygons:
  // square root of the area) cost more tests than they cull. Leaving them out
  // only makes a PVS larger, never wrong. Tuned on bigcity, whose window
  // frames and sills would otherwise be 60% of all occluders.
  double minOccluderSize = 1.0;     // metres
  double minPolygonArea = 0.0;      // m^2; smaller polygons are not occluders
  double coplanarTolerance = 1e-5;  // metres (relative to 1 + coordinate size) for grouping
};

OccluderSet extractOccluders(const Scene& scene, const OccluderOptions& options = {});

// Rounding margin for geometry of a given coordinate magnitude: far above the
// error of double arithmetic on float inputs, far below anything visible.
inline double occluderMargin(double magnitude) {
  return 1e-7 * (1.0 + magnitude);
}

// True if the open segment (a, b) passes through the occluder's region
// (strictly inside: grazing never blocks).
bool occluderBlocksSegment(const ConvexOccluder& o, const glm::dvec3& a, const glm::dvec3& b);

}  // namespace vistream
