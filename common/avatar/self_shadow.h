// Self-shadowing transfer vectors of an animated mesh, per vertex and per
// frame (Kautz, Lehtinen and Aila 2004, section 3): each vertex's blockers
// are rasterized into its visibility mask (hemisphere_raster.h) and the mask
// is integrated against the SH basis (transfer.h). Here every triangle of
// the mesh is a blocker of every vertex; triangles wholly at or below a
// vertex's tangent plane are rejected before rasterization.
//
// The reference: Monte Carlo transfer, `rays` cosine-weighted rays a vertex
// traced with Embree against the same mesh (stratified, deterministic).
//
// Thread safety: const methods may run concurrently; vertices are shaded in
// parallel (TBB) and the results do not depend on the thread count.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <memory>
#include <vector>

#include "common/avatar/hemisphere_raster.h"
#include "common/avatar/skinning.h"
#include "common/avatar/transfer.h"

namespace vistream {

struct SelfShadowOptions {
  int maskSide = 32;     // 16, 32 or 64
  int planeTable = 128;  // cube-map cells a side; 0: exact planes per pixel
  TransferOptions transfer;
  // Hierarchical culling (section 3.2): where blockers come with triangle
  // groups, a vertex skips every group whose bounding sphere lies wholly
  // below its tangent plane. The result is the same either way.
  bool cullGroups = true;
};

// Static triangle groups for hierarchical culling against the tangent plane
// (Kautz et al. 2004, section 3.2): clusters of up to kMaxTriangles nearby
// triangles, fixed once from a rest pose (meshoptimizer's meshlets), whose
// bounding spheres follow the animation (spheres(), once a frame). A vertex
// then rejects a whole group below its tangent plane with one test instead
// of transforming each of its triangles. Triangles meshoptimizer leaves out
// (degenerate ones) form a last group that is never culled.
struct TriangleGroups {
  static constexpr size_t kMaxTriangles = 16;
  std::vector<uint32_t> groupOf;                    // per triangle
  std::vector<uint32_t> vertexStart{0}, vertices;   // per group (CSR)
  std::vector<uint32_t> triangleStart{0}, members;  // per group (CSR): its triangles
  std::vector<uint8_t> neverCulled;                 // per group

  size_t size() const { return vertexStart.size() - 1; }
  bool empty() const { return size() == 0; }
  static TriangleGroups build(const std::vector<glm::uvec3>& triangles,
                              const std::vector<glm::vec3>& restPositions);
  // Per group, a bounding sphere (centre, radius) of its vertices at
  // `positions`; a never-culled group gets an infinite radius.
  void spheres(const std::vector<glm::vec3>& positions, std::vector<glm::vec4>& out) const;
};

struct SelfShadowStats {
  uint64_t vertices = 0;       // shaded
  uint64_t groupsCulled = 0;   // (vertex, group) pairs culled whole
  uint64_t blockerTests = 0;   // (vertex, triangle) pairs looked at
  uint64_t rasterized = 0;     // of those, drawn into a mask
  double rasterSeconds = 0.0;  // summed over threads
  double integrateSeconds = 0.0;
};

// The paper's two-level mesh hierarchy (section 3.2): near a vertex its
// blockers are the fine mesh's triangles within `ring` rings of it; the rest
// of the model blocks through a coarse mesh, without the coarse triangles
// whose area the fine ring covers (their parents). Both meshes index the
// same vertices (SkinnedMesh::subdivided keeps the coarse vertices first).
// Fine triangle t's coarse parent is parentOf[t].
struct ShadowHierarchy {
  std::vector<glm::uvec3> coarse;
  std::vector<uint32_t> ringStart, ringTriangles;  // per vertex (CSR): fine triangles
  std::vector<uint32_t> skipStart, skipTriangles;  // per vertex (CSR): coarse ones left out

  // For a mesh subdivided `levels` times from `coarse` into `split` children
  // a triangle (fine triangle t descends from coarse triangle
  // t / split^levels). ring: 1 or 2.
  static ShadowHierarchy build(const std::vector<glm::uvec3>& fine,
                               const std::vector<glm::uvec3>& coarse, int levels, int ring,
                               size_t vertices, int split = 4);
  double meanBlockers() const;  // ring plus coarse, a vertex
};

// Per vertex, the triangles that may block it, as lists: vertex v's are
// triangles[list[k]] for k in [start[v], start[v + 1]) (vertex indices of the
// posed mesh). The general form of the blocker sets above: every triangle,
// the mesh hierarchy, or a PVS cut from either.
struct VertexBlockers {
  std::vector<glm::uvec3> triangles;
  std::vector<uint32_t> start{0}, list;
  TriangleGroups groups;  // of `triangles`; empty: no culling

  // Groups `triangles` for culling, from the mesh at rest.
  void groupTriangles(const std::vector<glm::vec3>& restPositions) {
    groups = TriangleGroups::build(triangles, restPositions);
  }

  size_t vertices() const { return start.size() - 1; }
  double meanPerVertex() const;
  // Every triangle for every vertex (vertices x triangles entries: small meshes).
  static VertexBlockers everyTriangle(const std::vector<glm::uvec3>& triangles, size_t vertices);
  // The hierarchy's blockers: each vertex's fine ring, then the coarse
  // triangles the ring does not cover.
  static VertexBlockers of(const ShadowHierarchy& hierarchy, const std::vector<glm::uvec3>& fine);
};

// The paper's static per-vertex PVS (section 3.2, "PVS"): the blockers of
// `candidates` that add to the vertex's visibility mask in at least one of
// the sampled `poses` of the animation (positions and normals of the mesh
// the candidates index). Per pose, a vertex's candidates above its tangent
// plane are rasterized nearest first (by centroid distance) and each that
// sets a bit the ones before it left clear is kept. The mask is the OR of
// its blockers, so at every sampled pose the kept ones give exactly the
// mask of all of them; between sampled poses a blocker left out may be
// missed (the error this costs is measured, not bounded). Parallel (TBB).
VertexBlockers potentiallyVisibleBlockers(const VertexBlockers& candidates,
                                          const std::vector<PosedMesh>& poses,
                                          const SelfShadowOptions& options = {});

// What a shading run may take and give beyond the transfer vectors.
struct ShadeExtras {
  SelfShadowStats* stats = nullptr;  // out
  // Triangles form only: the hierarchy's blockers replace `triangles`
  // (which must be the fine mesh it was built for); without one, `groups`
  // (of `triangles`) lets whole groups be culled. The lists form takes
  // its groups from the lists.
  const ShadowHierarchy* hierarchy = nullptr;
  const TriangleGroups* groups = nullptr;
  // Shade only the vertices v with (*only)[v] != 0 (the paper shades only
  // the vertices of front-facing triangles: frontFacingVertices). The other
  // vertices' transfer vectors and masks are left as they are, so a pose
  // shaded in parts is completed in place; vectors shorter than the mesh
  // grow with zeros.
  const std::vector<uint8_t>* only = nullptr;
  // Out: every vertex's visibility mask, SelfShadowing::maskWords() words each (zeros for
  // vertices not shaded, unless `only` leaves them), for view-dependent (glossy) transfer later.
  std::vector<uint64_t>* masks = nullptr;
};

class SelfShadowing {
 public:
  explicit SelfShadowing(const SelfShadowOptions& options = {});
  const SelfShadowOptions& options() const { return options_; }
  int terms() const { return integrator_.terms(); }

  // Diffuse transfer vectors, terms() floats per vertex, of the mesh
  // (positions, unit normals per vertex) shadowing itself.
  void diffuse(const std::vector<glm::vec3>& positions, const std::vector<glm::vec3>& normals,
               const std::vector<glm::uvec3>& triangles, std::vector<float>& out,
               const ShadeExtras& extras = {}) const;
  // The same with each vertex's blockers from lists (a PVS).
  void diffuse(const std::vector<glm::vec3>& positions, const std::vector<glm::vec3>& normals,
               const VertexBlockers& blockers, std::vector<float>& out,
               const ShadeExtras& extras = {}) const;
  int maskWords() const { return (options_.maskSide * options_.maskSide + 63) / 64; }

 private:
  // The shadow loop: forEachBlocker(v, stats, block, blockEager) calls
  // block(triangle) for vertex v's blockers, or blockEager(triangle) for one
  // whose corners are all below `eager` (those vertices are put into v's
  // tangent frame once, not per triangle), and counts culled groups in stats.
  template <class ForEachBlocker>
  void run(const std::vector<glm::vec3>& positions, const std::vector<glm::vec3>& normals,
           std::vector<float>& out, const ShadeExtras& extras, size_t eager,
           ForEachBlocker&& forEachBlocker) const;
  SelfShadowOptions options_;
  std::unique_ptr<PlaneMaskTable> table_;
  TransferIntegrator integrator_;
};

// The vertices of the triangles that face a viewer looking along `view`
// (any length): a triangle faces it when its geometric normal points against
// `view`. The paper shades only these; the others are hidden from that
// viewer on a closed, outward-wound model.
std::vector<uint8_t> frontFacingVertices(const std::vector<glm::vec3>& positions,
                                         const std::vector<glm::uvec3>& triangles,
                                         const glm::vec3& view);
// The same for a viewer at the point `eye` (perspective): a triangle faces it
// when `eye` lies strictly in front of its plane.
std::vector<uint8_t> verticesFacing(const std::vector<glm::vec3>& positions,
                                    const std::vector<glm::uvec3>& triangles, const glm::vec3& eye);

// Monte Carlo diffuse transfer of the same mesh: `rays` cosine-weighted rays
// a vertex (a stratified grid, rotated per vertex by a hash of its index),
// leaving the vertex a hair above its tangent plane.
// `seed` varies the rotation (two runs with different seeds are
// independent estimates). With `only`, just the vertices v with
// (*only)[v] != 0 are traced; the rest get zeros (a converged reference on
// a sample of a large model's vertices).
void monteCarloTransfer(const std::vector<glm::vec3>& positions,
                        const std::vector<glm::vec3>& normals,
                        const std::vector<glm::uvec3>& triangles, uint32_t rays, int orders,
                        std::vector<float>& out, uint64_t seed = 0,
                        const std::vector<uint8_t>* only = nullptr);

// The same for glossy transfer (TransferIntegrator::glossy): each ray
// weighted by the normalized Phong lobe (e + 1) / (2 pi) (r . s)^e about
// vertex v's reflected direction reflected[v] (unit, world).
void monteCarloGlossyTransfer(const std::vector<glm::vec3>& positions,
                              const std::vector<glm::vec3>& normals,
                              const std::vector<glm::uvec3>& triangles,
                              const std::vector<glm::vec3>& reflected, float exponent,
                              uint32_t rays, int orders, std::vector<float>& out, uint64_t seed = 0,
                              const std::vector<uint8_t>* only = nullptr);

// Mean over vertices of |a - b| / |b| for transfer vectors of `terms`
// coefficients (vertices where b is zero are left out).
double meanRelativeL2(const std::vector<float>& a, const std::vector<float>& b, int terms);

}  // namespace vistream
