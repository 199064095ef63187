// Sampled visibility ground truth for a view cell.
//
// Viewpoints are sampled in a closed axis-aligned box: its 8 corners, its 6
// face centres, its centre, then random interior points up to the requested
// count. From each, R x R rays per cube-map face (through pixel centres) find
// the first face hit. The union of those face IDs is a lower bound of the
// exact visible set: every conservative PVS must contain it.
//
// Viewpoints inside solid geometry (see insideSolid) are skipped and
// counted: no one stands there.
//
// Thread safety: sampleVisibleFaces may run concurrently; it uses TBB internally.
#pragma once

#include <cstdint>
#include <vector>

#include "common/core/box.h"
#include "common/raycast/ray_query.h"

namespace vistream {

struct SampledVisibilityOptions {
  size_t points = 32;    // viewpoints, including the 15 fixed ones
  int resolution = 128;  // rays per cube-map face side
  uint64_t seed = 1;
};

struct SampledVisibility {
  std::vector<uint32_t> faces;  // sorted, unique face IDs
  size_t viewpoints = 0;        // viewpoints used
  size_t insideSolid = 0;       // viewpoints skipped because they lie inside solid geometry
  uint64_t rays = 0;
  uint64_t hits = 0;
  double timeMs = 0.0;
};

// The viewpoints sampleVisibleFaces uses for a cell (before the inside-solid test).
std::vector<glm::vec3> cellViewpoints(const Box3f& cell, size_t points, uint64_t seed);

// True if the point lies inside solid geometry: both rays of one axis, or
// most of the six axis rays, hit back faces. A point on a surface counts as
// outside.
bool insideSolid(const RayQuery& rays, const glm::vec3& point);

SampledVisibility sampleVisibleFaces(const RayQuery& rays, const FlatTriangles& triangles,
                                     const Box3f& cell,
                                     const SampledVisibilityOptions& options = {});

}  // namespace vistream
