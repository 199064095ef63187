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
//
// Batches (makeBatchedEmbreeRayQuery): a scene whose triangles come and go,
// as a streaming client's do. Each batch is one Embree geometry (a BVH of its
// own, built with high quality) in a two-level scene (build quality low), so
// commit() rebuilds only the geometries added or changed and the top level.
// Hits, ties and precision are those of the static back end above: the same
// triangles give the same answers however they were batched.
#pragma once

#include <cstdint>
#include <memory>
#include <span>

#include "common/raycast/ray_query.h"

namespace vistream {

// A RayQuery over triangles added and removed in batches. Triangle indices
// are those of the FlatTriangles given to addBatch (a batch is a contiguous
// range of them, copied: the FlatTriangles need not outlive the call).
// Changes become visible to queries at commit().
//
// Thread safety: queries are const and may run concurrently with each other,
// never with addBatch, removeTriangles or commit.
class BatchedRayQuery : public RayQuery {
 public:
  // Adds triangles [first, first + count) of `triangles`; the range must not
  // overlap a batch added before (VS_CHECK). Degenerate triangles are never hit.
  virtual void addBatch(const FlatTriangles& triangles, uint32_t first, uint32_t count) = 0;
  // Removes triangles by index; indices never added or already removed are
  // ignored. Rebuilds the geometry of each batch touched (cost: its size).
  virtual void removeTriangles(std::span<const uint32_t> triangles) = 0;
  // Builds what changed; throws std::runtime_error if Embree fails (out of memory).
  virtual void commit() = 0;
  // Batches holding at least one triangle that can be hit.
  virtual size_t batchCount() const = 0;
};

std::unique_ptr<BatchedRayQuery> makeBatchedEmbreeRayQuery();

// Number of errors Embree has reported through vistream's device error
// handler since the process started, over every EmbreeRayQuery. Each error is
// also logged with spdlog at error level. Thread-safe.
uint64_t embreeErrorCount();

}  // namespace vistream
