// A ray query over the scene's surface as the welded topology reads it
// (weldedSurface(), common/world/solids.h): the cracks a model leaves at
// T-junctions and between corners a few millimetres apart are closed.
//
// Why: real models are not watertight in floats. Where a wall's corner lies
// on the long side of its neighbour, rays slip through a crack a fraction of
// a millimetre wide and reach the inside of the building. The solids that
// back-face culling and fused occlusion rely on (common/world/back_faces.h,
// server/visibility/horizon_fusion.h) are read with those cracks closed, so
// the visibility oracles that check them sample this surface too.
//
// Hits name the original triangles (indices into the FlatTriangles given),
// with barycentrics and the geometric normal of the original triangle at the
// hit point; allHits lists each original triangle once, at its nearest hit.
//
// Ownership: keeps a reference to `triangles`, which must outlive it.
// Thread safety: as the Embree back end (const queries from any thread).
#pragma once

#include <memory>

#include "common/raycast/ray_query.h"
#include "common/scene/scene.h"

namespace vistream {

// `weldTolerance` in metres, finite and not negative (VS_CHECK); 0 leaves
// the surface as it is (degenerate triangles still left out).
std::unique_ptr<RayQuery> makeSealedRayQuery(const FlatTriangles& triangles, double weldTolerance);

}  // namespace vistream
