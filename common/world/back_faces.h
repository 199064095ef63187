// Which triangles have the inside of a solid right behind them: the
// triangles back-face culling may drop for a view cell that lies behind
// their plane and above the solid's floor (server/visibility/epsilon_pvs.h),
// seen from viewpoints outside the solid.
//
// Two proofs, tried in this order for each non-degenerate triangle:
//
//  - Orientation. The triangle lies in a closed, manifold, consistently
//    OUTWARD welded component (Solids::weldedComponents()): its back side
//    faces the inside. Such a component's group is sealed, so an
//    enclosure, whose inside no served viewpoint lies in.
//
//  - Parity. The triangle lies in an enclosure E (Solids::enclosureOf(): a
//    welded parity group that is sealed, or open only at its base), and
//      (a) no other triangle of E comes within the clearance c of the
//          triangle shrunk by c (clipped to the slab |distance| <= c of its
//          plane and projected onto it), and its inradius exceeds 2c;
//      (b) from the point c/2 behind its incentre, which lies above E's
//          floor (Solids::enclosureFloor()), upward rays cross E an odd
//          number of times (a strict majority of the kSolidTestDirections
//          directions), and from the point c/2 in front of it, if that lies
//          above the floor too, an even number (every direction). A bottom
//          face in the plane of an open base has only its back above.
//    By (a) the points within c behind the shrunk triangle form a connected
//    set that no triangle of E meets, so parity is the same over all of it
//    and by (b) odd. Take a viewpoint p outside E (parity even: outside
//    its bounding box, or any viewpoint the PVS contract serves, which
//    excludes the inside and surface of every enclosure,
//    Solids::unservedViewpoint) and above its floor, and a line from p reaching the shrunk
//    triangle from behind at q: points just before q are in that set, so the
//    segment from p to them changes parity and, staying above the cap,
//    crosses a real triangle of E before q. The triangle is never the first
//    surface the line meets.
//
// What the parity proof does not cover, the same price the welded topology
// already pays (common/world/solids.h): lines through cracks narrower than
// the weld tolerance, or through the gap of at most the tolerance between a
// base-open enclosure's lowest edges and its cap, count as blocked; and a
// line reaching a triangle within c of its edges is covered only if the
// neighbouring triangles close the solid there. The parity test sums rays
// over the real triangles (RayQuery), not over the welded ones.
//
// Units: metres. Thread safety: a pure function of its inputs.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "common/core/box.h"
#include "common/raycast/ray_query.h"
#include "common/scene/scene.h"
#include "common/world/solids.h"

namespace vistream {

struct BackFaceOptions {
  // Metres: the clearance c above. Raised where floats are coarser (far
  // from the origin) to 8 ulps of the triangle's largest coordinate.
  // Positive and finite (VS_CHECK).
  double clearance = 1e-3;
  bool parity = true;  // false: the orientation proof alone
};

// The solid behind each one-sided triangle. A solid is a welded component
// (orientation proof) or an enclosure (parity proof); a viewpoint may have
// a triangle culled only from outside the solid and strictly above its
// floor.
struct BackFaceSolids {
  std::vector<uint32_t> solidOf;  // by triangle: index into floor, or kNoHit
  std::vector<float> floor;       // by solid: y a viewpoint must exceed (-inf: none)
  size_t byOrientation = 0;       // triangles proved one-sided by orientation
  size_t byParity = 0;            // ... by parity (and not by orientation)
};

// `solids` and `rays` must be built over `triangles`.
BackFaceSolids backFaceSolids(const FlatTriangles& triangles, const Solids& solids,
                              const RayQuery& rays, const BackFaceOptions& options = {});

}  // namespace vistream
