// The Embree back end (makeEmbreeRayQuery, declared in ray_query.h with the
// other back ends): what it adds to and how it rounds the shared contract.
//
// Precision: Embree intersects in float (robust mode, a closed watertight
// Pluecker test), the oracle in double. Hence, relative to the oracle:
//  - t agrees to float precision (a few ulps of the hit distance).
//  - A hit within 4 to 8 float ulps outside [tnear, tfar] still counts, with
//    its t clamped into the interval, so a hit exactly on a bound is never lost
//    to rounding.
//  - firstHit ties: triangles hit within about 32 ulps of the nearest t
//    (relative to t plus the hit triangle's size over |dir|) count as tied and
//    the smaller index wins. Rays exactly through shared edges and vertices
//    therefore report the same triangle as the oracle when the arithmetic is
//    exact (e.g. integer vertices, dyadic rays).
//  - allHits: a ray exactly through an edge or vertex reports every triangle
//    sharing it when the arithmetic is exact, as the oracle does. Otherwise
//    (and so do the oracle's double-precision answers) a ray within rounding
//    of an edge reports one side or both, and the two back ends may differ.
//  - Nothing slips through a seam: a ray through a shared edge or vertex
//    always hits at least one of the triangles sharing it.
// Cost: firstHit runs a second, short traversal around every hit to resolve
// ties (about a quarter to a third of the firstHit time on the cities of
// raycast_bench); rays with a zero direction component are traversed two or
// four times (see embree_ray_query.cpp), so axis-parallel rays cost more.
// Batched queries use Embree's stream path.
//
// Thread safety: as in ray_query.h. Construction may run concurrently too; all
// queries share one process-wide Embree device. Errors Embree reports are
// logged with spdlog and counted (embreeErrorCount); a scene that fails to
// build (e.g. out of memory) throws std::runtime_error from makeEmbreeRayQuery.
#pragma once

#include <cstdint>

namespace vistream {

// Number of errors Embree has reported through vistream's device error
// handler since the process started, over every EmbreeRayQuery. Each error is
// also logged with spdlog at error level. Thread-safe.
uint64_t embreeErrorCount();

}  // namespace vistream
