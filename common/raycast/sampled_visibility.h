// Sampled visibility ground truth for a view cell.
//
// Viewpoints are sampled in a closed axis-aligned box: its 8 corners, its 6
// face centres, its centre, then random interior points up to the requested
// count. From each, R x R rays per cube-map face (through pixel centres) find
// the first face hit. The union of those face IDs is a lower bound of the
// exact visible set: every conservative PVS must contain it. Faces count
// as open sets: a ray whose first hit lies on the edge of a triangle turned
// away from it only grazes that edge (over a roof's rim, through the corner
// of a box) and credits a triangle turned towards it at the same distance,
// or nothing.
//
// Probes (SampledVisibilityOptions::probeFaces): a cube map misses what is
// smaller than its pixels, a facade's sliver between two far buildings, a
// roof detail 150 m away. Faces named as probes are also aimed at: from
// every viewpoint, one ray to each of `probeSamples` points spread over each
// of their triangles (the centroid first, then a Halton sequence). A ray's
// first hit is credited by the same rule as a cube-map ray, so probes only
// add faces that are truly seen. PVS checks probe the PVS's own faces.
//
// Viewpoints for which SampledVisibilityOptions::skipViewpoint answers true
// are skipped and counted. PVS checks pass the PVS contract's rule
// (Solids::unservedViewpoint, common/world/solids.h): no one is served
// inside solid geometry.
//
// Thread safety: sampleVisibleFaces may run concurrently; it uses TBB internally.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "common/core/box.h"
#include "common/raycast/ray_query.h"

namespace vistream {

struct SampledVisibilityOptions {
  size_t points = 32;    // viewpoints, including the 15 fixed ones
  int resolution = 128;  // rays per cube-map face side
  uint64_t seed = 1;
  // Viewpoints to leave out (empty: none).
  std::function<bool(const glm::vec3&)> skipViewpoint;
  // Faces (any order) to aim rays at from every viewpoint; empty: none.
  std::vector<uint32_t> probeFaces;
  int probeSamples = 8;  // points aimed at per triangle of a probe face
};

struct SampledVisibility {
  std::vector<uint32_t> faces;  // sorted, unique face IDs
  size_t viewpoints = 0;        // viewpoints used
  size_t insideSolid = 0;       // viewpoints skipped by skipViewpoint
  uint64_t rays = 0;
  uint64_t hits = 0;
  uint64_t probeRays = 0;  // of `rays`, aimed at probe faces
  size_t probeOnly = 0;    // faces of `faces` only the probes found
  double timeMs = 0.0;
};

// The viewpoints sampleVisibleFaces uses for a cell (before skipViewpoint).
std::vector<glm::vec3> cellViewpoints(const Box3f& cell, size_t points, uint64_t seed);

// The triangle a ray sees at its first hit `h`, or kNoHit: the rule of
// open faces above. When `h` faces away from the ray, a triangle facing the
// ray no farther than the tie window beyond it (ray_query.h resolves ties
// within float error to the smaller index, which can credit the back of a
// roof over the wall that meets it at the rim, or a sliver a fraction of a
// millimetre behind a wall) is seen instead; failing that, a hit on the
// triangle's boundary only grazes its edge and credits nothing. `scratch`
// is reused between calls. Every visibility oracle (this sampler, the load
// tester's miss check) applies it.
uint32_t seenTriangle(const RayQuery& rays, const Ray& ray, const Hit& h,
                      std::vector<Hit>& scratch);

SampledVisibility sampleVisibleFaces(const RayQuery& rays, const FlatTriangles& triangles,
                                     const Box3f& cell,
                                     const SampledVisibilityOptions& options = {});

}  // namespace vistream
