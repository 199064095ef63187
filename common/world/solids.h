// Which parts of the static geometry are solids, decided without trusting
// face winding where it cannot be trusted.
//
// The triangles are welded by exact position and joined into components
// across manifold edges (edges used by exactly two triangles): a sheet and
// the boxes standing on it, or two boxes sharing an edge, stay apart. Each
// component is classified from the edges of its triangles:
//  - non-manifold: some edge is used by more than two triangles;
//  - open: some edge is used by one triangle only (a sheet, a box without
//    its bottom face, a wall with a door hole);
//  - inconsistent: closed and manifold, but some edge is used twice in the
//    same direction (part of the surface is wound the other way);
//  - closed outward / closed inward: closed, manifold and consistently
//    oriented, by the sign of the enclosed signed volume.
// Orientation is trusted only where these hold, and there only to report
// which way a closed mesh is wound (closed inward is usually a solid
// exported inside out, e.g. through a mirroring transform). The inside test
// uses no winding at all, so free space is the same whichever way any face
// is wound: a point is inside a parity group (components joined at
// non-manifold edges, so two boxes sharing a face count as one) when rays in
// a strict majority of kSolidTestDirections upward-pointing directions cross
// the group an odd number of times. For closed meshes parity is exact in
// every direction; upward directions also make it exact for the common open
// cases (boxes without a bottom face, buildings without a ground surface)
// and never count a floor or terrain sheet below the point.
//
// A group is closed when all its components are closed outward or inward.
//
// Sealed solids are a second reading, for the occluders that fuse solids
// (server/visibility/horizon_fusion.h), made with a weld tolerance
// (SolidsOptions::weldTolerance, 1 cm by default) because real models are
// not watertight in floats: the polygons of a LoD2 building are
// triangulated one by one, so the corner of one wall lies on the long side
// of the next (a T-junction) or a few millimetres off it, and row houses
// leave out the party walls so that only the block is closed. Corners
// within the tolerance are one vertex (each joins the nearest earlier
// representative, so welding never chains), a triangle side passing within
// the tolerance of a boundary vertex, away from its ends, is cut there into
// pieces that the neighbour's sides share, and a triangle two of whose
// corners weld belongs to no solid. Components and parity groups are then
// formed as above; a group is sealed when every edge piece of it is used an
// even number of times (a cycle modulo 2, whatever the winding or
// manifoldness): parity along a ray then does not depend on the ray, and a
// segment from outside to inside crosses one of its triangles. The welded
// components (weldedComponents()) serve back-face culling, which needs a
// closed, manifold, consistently outward one.
//
// Enclosures are a wider reading of the welded topology, for back-face
// culling by parity (common/world/back_faces.h): the welded parity groups
// that are sealed, and those open only at their base, every edge piece used
// an odd number of times lying within the tolerance above the group's lowest
// point (a LoD2 building without its ground surface, a box without its
// bottom face). Closed by a cap at the base, such a group is a cycle modulo
// 2 as well, and a segment that stays above the cap (enclosureFloor()) meets
// only real triangles of it: parity along such segments, and along upward
// rays from above the floor, is that of a sealed solid. The price: a
// crack narrower than the tolerance counts as closed, so a line of sight
// through it may be taken as blocked. The inside tests above stay on the
// exact topology: welding joins the floor and ceiling sheets of an interior
// to its wall boxes, and a room would read as the inside of a solid.

#pragma once

#include <array>
#include <cstdint>
#include <glm/glm.hpp>
#include <string>
#include <vector>

#include "common/core/box.h"
#include "common/raycast/ray_query.h"
#include "common/scene/scene.h"
#include "common/spatial/xz_grid.h"

namespace vistream {

enum class SolidClass : uint8_t { ClosedOutward, ClosedInward, Open, NonManifold, Inconsistent };
inline constexpr size_t kSolidClassCount = 5;
// "closed_outward", "closed_inward", "open", "non_manifold", "inconsistent".
const char* solidClassName(SolidClass c);

inline constexpr int kSolidTestDirections = 9;
// The upward unit directions the parity tests cast rays along.
const std::array<glm::vec3, kSolidTestDirections>& solidTestDirections();

struct SolidComponent {
  SolidClass kind = SolidClass::Open;
  Box3f bounds;
  size_t triangles = 0;
  size_t faces = 0;           // distinct face IDs
  double signedVolume = 0.0;  // m^3, positive when wound outward (meaningful when closed)
};

// Components, triangles and faces per class (indexed by SolidClass).
struct SolidCensus {
  std::array<size_t, kSolidClassCount> components{};
  std::array<size_t, kSolidClassCount> triangles{};
  std::array<size_t, kSolidClassCount> faces{};
};

struct SolidsOptions {
  // Metres, for sealed solids: corners closer than this weld, and sides
  // passing this close to a boundary vertex are cut there (see above). 0:
  // exact positions only. Finite and not negative (VS_CHECK).
  double weldTolerance = 0.01;
};

// The surface as the welded topology reads it (`tol` as
// SolidsOptions::weldTolerance): corners within tol are one vertex at their
// representative's position, a triangle whose side passes within tol of a
// boundary vertex is cut there (fanned from the centroid of its boundary
// points), and degenerate and collapsed triangles are left out. Each piece
// keeps its triangle's face and object; originalOf[piece] is its triangle's
// index in `triangles`. Rays over it do not leak through the cracks of
// T-junctions and corners a few millimetres apart (sealed_surface.h).
FlatTriangles weldedSurface(const FlatTriangles& triangles, double tol,
                            std::vector<uint32_t>& originalOf);

class Solids {
 public:
  // Degenerate triangles take no part (they are never hit by rays).
  static Solids build(const FlatTriangles& triangles, const SolidsOptions& options = {});

  const std::vector<SolidComponent>& components() const { return components_; }
  // Component of a triangle (index into FlatTriangles); kNoHit for a degenerate one.
  uint32_t componentOf(uint32_t triangle) const { return componentOf_[triangle]; }
  SolidCensus census() const;
  // Sealed solids (see above): the sealed group of a triangle, or kNoHit.
  uint32_t sealedOf(uint32_t triangle) const { return sealedOf_[triangle]; }
  size_t sealedCount() const { return sealedBounds_.size(); }
  const Box3f& sealedBounds(uint32_t sealed) const { return sealedBounds_[sealed]; }
  size_t sealedTriangles() const;
  // The components of the welded topology, classified as components() are.
  const std::vector<SolidComponent>& weldedComponents() const { return weldedComponents_; }
  uint32_t weldedComponentOf(uint32_t triangle) const { return weldedComponentOf_[triangle]; }
  // Enclosures (see above): the enclosure of a triangle, or kNoHit.
  uint32_t enclosureOf(uint32_t triangle) const { return enclosureOf_[triangle]; }
  size_t enclosureCount() const { return enclosureBounds_.size(); }
  const Box3f& enclosureBounds(uint32_t enclosure) const { return enclosureBounds_[enclosure]; }
  // The height (y, metres) the cap of an enclosure open at its base reaches:
  // the highest point of its open base edges (at most its lowest point plus
  // the weld tolerance). -infinity for a sealed one.
  float enclosureFloor(uint32_t enclosure) const { return enclosureFloor_[enclosure]; }
  // The weld tolerance this was built with (SolidsOptions::weldTolerance).
  double weldTolerance() const { return weldTolerance_; }

  // True if `point` lies inside a solid component. `rays` must answer over
  // the same triangles this was built from. A point on a surface is outside
  // by convention.
  bool inside(const RayQuery& rays, const glm::vec3& point) const;
  // True if `point` lies inside or on the surface of a closed solid: a
  // parity group whose components are all closed, manifold and consistently
  // oriented (outward or inward); an eye on a wall's surface looks into the
  // wall.
  bool insideClosed(const RayQuery& rays, const glm::vec3& point) const;
  // True if `point` lies above an enclosure's floor and inside it (parity
  // of its triangles along a strict majority of the upward test
  // directions), or on an enclosure's surface: the welded reading of a
  // building, party walls and T-junction cracks aside.
  bool insideEnclosure(const RayQuery& rays, const glm::vec3& point) const;
  // The viewpoint rule of the PVS contract (server/visibility/epsilon_pvs.h):
  // a viewer inside any solid (inside()), inside or on the surface of a
  // closed one (insideClosed()), or inside or on an enclosure
  // (insideEnclosure()) is not served.
  // Equal to inside() || insideClosed() || insideEnclosure().
  bool unservedViewpoint(const RayQuery& rays, const glm::vec3& point) const;

  // Parity over the enclosures along one ray, the count every enclosure
  // test above and elsewhere (back faces, horizons) is made of: the
  // enclosures whose triangles `ray` crosses an odd number of times, into
  // `odd`, sorted and each once (hits of triangles this was not built from
  // count for nothing). False, with `odd` empty, if the ray starts on a
  // surface (a hit at t = 0, on any triangle the ray query holds).
  bool oddEnclosures(const RayQuery& rays, const Ray& ray, std::vector<uint32_t>& odd) const;
  // The number of test directions (solidTestDirections()) along which the
  // upward ray from `point` crosses `enclosure` an odd number of times; -1
  // if `point` lies on a surface. Each ray reaches just past the
  // enclosure's bounds (their diagonal plus the point's distance from
  // their centre, plus a metre), so the rest of the scene costs nothing.
  int enclosureVotes(const RayQuery& rays, const glm::vec3& point, uint32_t enclosure) const;

 private:
  std::vector<uint32_t> componentOf_;
  std::vector<SolidComponent> components_;
  std::vector<uint32_t> groupOf_;     // parity group of each component
  std::vector<Box3f> groupBounds_;    // by group
  std::vector<uint8_t> groupClosed_;  // by group: every component closed and consistently oriented
  std::vector<uint8_t> groupSealed_;  // by group: a cycle modulo 2
  XzGrid grid_;                       // groups by X/Z cell of their bounds
  std::vector<uint32_t> sealedOf_;    // by triangle: sealed group of the welded topology
  std::vector<Box3f> sealedBounds_;   // by sealed group
  std::vector<uint32_t> weldedComponentOf_;
  std::vector<SolidComponent> weldedComponents_;
  std::vector<uint32_t> enclosureOf_;    // by triangle
  std::vector<Box3f> enclosureBounds_;   // by enclosure
  std::vector<float> enclosureFloor_;    // by enclosure
  std::vector<uint8_t> groupEnclosure_;  // by group, after peeling: none, sealed, base-open
  std::vector<uint8_t> peeled_;          // by triangle: peeled off its group
  std::vector<float> groupBaseTop_;      // by group: highest point of its open base
  XzGrid enclosureGrid_;                 // enclosures by X/Z cell of their bounds
  double weldTolerance_ = 0.0;

  // enclosureOf() of a ray's hit: kNoHit for a triangle not built from.
  uint32_t enclosureOfHit(uint32_t triangle) const {
    return triangle < enclosureOf_.size() ? enclosureOf_[triangle] : kNoHit;
  }

  // Components and parity groups of the topology welded within `tol`.
  static Solids classify(const FlatTriangles& triangles, double tol);

  // closedOnly: only closed groups are candidates; closedSurfaceInside: a
  // point on a closed group's surface counts as inside.
  bool insideGroup(const RayQuery& rays, const glm::vec3& point, bool closedOnly,
                   bool closedSurfaceInside) const;
};

}  // namespace vistream
