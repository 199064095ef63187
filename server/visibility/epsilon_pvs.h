// The conservative visibility superset of an epsilon-neighbourhood: Cohen-Or
// and Zadicario, "Visibility Streaming for Network-based Walkthroughs" (1998),
// sections 3-4.
//
// A view cell is a closed axis-aligned box. An occludee (an object's bounding
// box, or a face) is culled only if ONE convex occluder blocks every line of
// sight from the cell to the occludee. For convex occluders the set of
// viewpoints from which a point is hidden is convex, and so is the set of
// points hidden from a viewpoint, so blocking the lines between the cell's
// corners and the occludee's vertices hides the occludee from every point of
// the cell. The PVS is therefore valid for any viewpoint in the closed cell
// outside closed solids, and any view direction (frustum culling stays on
// the client).
//
// Viewpoints inside solids, on the surface of closed ones, or inside or on
// an enclosure (a building as the welded reading sees it, open at its base
// or not) are not served (Solids::unservedViewpoint, common/world/solids.h).
// A solid
// occluder is the inside of a closed mesh: it blocks a line only because the
// line must cross the mesh's surface to enter it, which holds for viewpoints
// outside it. A cell that reaches into a closed building (a street cell
// 0.4 m into a facade) therefore misses what is seen from inside the
// building (its far wall from behind); no viewer stands there. The same
// holds inside open solids (a wall box without its bottom face) and for an
// eye on a closed solid's surface, which looks into the solid.
//
// Back faces (PvsOptions::backFaces, on by default): a face is culled when
// every non-degenerate triangle of it has the inside of one solid right
// behind it (common/world/back_faces.h: a closed, consistently outward
// component, or, proved triangle by triangle by parity, a welded group that
// is sealed or open only at its base, as LoD2 buildings without a ground
// surface are), the closed cell lies strictly behind every triangle's plane
// (by a rounding margin) and lies above the solid's floor (a base-open
// solid's cap). From a served viewpoint of such a cell (outside the solid
// and off its surface: the cell may still reach into the building), a line
// reaching the face from behind was inside the solid just before, so
// it crossed the solid's surface earlier and the face is not the first thing
// it meets. Solids are read with corners welded and T-junctions cut within
// 1 cm, so cracks narrower than that count as closed; the oracles that check
// the PVS sample the same sealed surface (common/world/sealed_surface.h).
// Faces of open, non-manifold and inward-wound parts stay two-sided, as do
// faces with the solid on both sides (coincident walls) or cut by another
// triangle of their solid.
//
// Solids fused within a plane (PvsOptions::planarFusion, on by default;
// server/visibility/planar_fusion.h): a face no single occluder hides is
// tested against each plane that faces of several solid occluders lie in
// (a wall of patches, a wall and its lintel), with the cell in front and
// the face behind; the union of their cross-sections just behind the plane
// must cover the shaft's footprint there.
//
// The paper's accelerations, each switchable (PvsOptions):
//  - bounding-box stage: an object whose bounding box is hidden is culled
//    with all its faces before any face is tested;
//  - incremental candidate set: the first line collects every occluder it
//    crosses through a kD-tree over the occluders; later lines only test the
//    survivors;
//  - occluded objects are dropped as occluders (objects are processed near
//    to far, so hidden near objects stop being tried for far ones);
//  - redundant lines removed: of the corner-vertex lines only those that can
//    lie on the convex hull of cell and occludee are cast. A line (c, v) is
//    kept if some direction n has c among the cell's minimisers of n.x and v
//    among the occludee's; if another line were blocked and this one not, a
//    plane separating it from the occluder would give such an n (see the
//    proof in epsilon_pvs.cpp). The pairs depend only on the occludee's shape,
//    so they are computed once per face, not per cell;
//  - large-occluder selection: only the K occluders with the largest solid
//    angle seen from the cell centre;
//  - coarse-to-fine cells: a fine cell inside a coarse one only tests the
//    faces of the coarse cell's PVS (PvsOptions::candidateFaces).
//
// Faces without area (PvsOptions::faceless): a face whose every triangle is
// degenerate (repeated corners, or zero area to 1e-12 of its longest edge
// squared: common/scene/scene.h) has no area to be seen by: no ray of the
// ray casters or of the oracles hits it, the software rasterizer skips it,
// and OpenGL lights at most stray pixels along its segment. It is in no PVS
// (the loader keeps such faces and counts them).
//
// Dynamic objects are never culled and never occlude: their faces are always
// in the PVS. Thread safety: compute() is const and may run concurrently.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/core/box.h"
#include "common/core/stats_fields.h"
#include "common/scene/scene.h"
#include "common/spatial/kdtree.h"
#include "common/world/static_world.h"
#include "server/visibility/occluders.h"

namespace vistream {

class HorizonFusion;
class PlanarFusion;

struct PvsOptions {
  bool boxStage = true;               // --no-bbox turns it off
  bool incremental = true;            // --no-incremental
  bool dropOccludedOccluders = true;  // --no-redundant-occluders
  bool removeRedundantLines = true;   // --no-redundant-rays
  size_t largeOccluders = 0;          // 0: every occluder; K: the K largest by solid angle
  bool backFaces = true;              // --no-back-faces: keep faces that face away from the cell
  bool fusion = true;                 // run the fused stage, when EpsilonPvs has one (setFusion)
  // --keep-faces-without-area: faces all of whose triangles are degenerate
  // stay in the PVS (the paper's method keeps every face it cannot cull).
  bool faceless = true;
  // --no-planar-fusion: solids fused within a plane (planar_fusion.h), run
  // only where no occlusion horizons follow (interiors): on the cities it
  // culled nothing the back faces had left (bench, 4 m cells: city1, city2,
  // delfshaven, bigcity) at up to 80 ms a cell (bigcity).
  bool planarFusion = true;
  // Coarse-to-fine: when non-null, only these faces (sorted) can be in the PVS.
  const std::vector<uint32_t>* candidateFaces = nullptr;
};

struct PvsStats {
  double timeMs = 0.0;
  double boxStageMs = 0.0;
  double faceStageMs = 0.0;
  size_t occluders = 0;           // occluders available to this cell
  size_t occludersUsed = 0;       // distinct occluders that culled something
  uint64_t linesCast = 0;         // lines of sight cast (traversed or tested)
  uint64_t lineBoxTests = 0;      // line/occluder tests in the bounding-box stage
  uint64_t linePolygonTests = 0;  // line/occluder tests in the face stage
  size_t boxes = 0;               // occludee groups tested in the box stage
  size_t boxesOccluded = 0;
  size_t boxesOccludedByFirst = 0;  // hidden by the first candidate tried
  // The same for objects whose bounding box is one occludee (not split into
  // groups): the "bounding boxes" of the paper's Table 1.
  size_t objectBoxes = 0;
  size_t objectBoxesOccluded = 0;
  size_t objectBoxesOccludedByFirst = 0;
  size_t faces = 0;          // faces considered
  size_t facesOccluded = 0;  // culled in total (box stage included)
  size_t facesCulledByBoxStage = 0;
  size_t facesBackFacing = 0;  // culled because they face away from the whole cell
  size_t facesFused = 0;       // culled by the fused stage (hidden by several occluders together)
  double fusionMs = 0.0;
  size_t facesPlanar = 0;       // culled by solids fused within a plane (in the face stage)
  size_t facesWithoutArea = 0;  // left out: every triangle degenerate, seen from nowhere

  // Every field above, once: `vistream-pvs cell` prints its JSON and its
  // table from this list (common/core/stats_output.h).
  template <class F>
  void forEachField(F&& f) const {
    f(StatField{"time_ms", "time", "ms"}, timeMs);
    f(StatField{"box_stage_ms", "box stage", "ms"}, boxStageMs);
    f(StatField{"face_stage_ms", "face stage", "ms"}, faceStageMs);
    f(StatField{"occluders", "occluders available", ""}, occluders);
    f(StatField{"occluders_used", "occluders used", ""}, occludersUsed);
    f(StatField{"lines_cast", "lines cast", ""}, linesCast);
    f(StatField{"line_box_tests", "line/box tests", ""}, lineBoxTests);
    f(StatField{"line_polygon_tests", "line/polygon tests", ""}, linePolygonTests);
    f(StatField{"boxes", "boxes tested", ""}, boxes);
    f(StatField{"boxes_occluded", "boxes occluded", ""}, boxesOccluded);
    f(StatField{"boxes_occluded_by_first_occluder", "boxes occluded by the first occluder", ""},
      boxesOccludedByFirst);
    f(StatField{"object_boxes", "object boxes tested", ""}, objectBoxes);
    f(StatField{"object_boxes_occluded", "object boxes occluded", ""}, objectBoxesOccluded);
    f(StatField{"object_boxes_occluded_by_first_occluder",
                "object boxes occluded by the first occluder", ""},
      objectBoxesOccludedByFirst);
    f(StatField{"faces_total", "faces considered", ""}, faces);
    f(StatField{"faces_occluded", "faces occluded", ""}, facesOccluded);
    f(StatField{"faces_culled_by_box_stage", "faces culled by box stage", ""},
      facesCulledByBoxStage);
    f(StatField{"faces_back_facing", "faces facing away from the cell", ""}, facesBackFacing);
    f(StatField{"faces_fused", "faces hidden by fused occluders", ""}, facesFused);
    f(StatField{"fusion_ms", "fusion stage", "ms"}, fusionMs);
    f(StatField{"faces_planar", "faces hidden by solids fused in a plane", ""}, facesPlanar);
    f(StatField{"faces_without_area", "faces without area", ""}, facesWithoutArea);
  }
};
// 22 fields of 8 bytes: a field added above must be added to forEachField too.
static_assert(sizeof(PvsStats) == 22 * 8, "PvsStats changed: update PvsStats::forEachField");

struct PvsResult {
  std::vector<uint32_t> faces;    // sorted face IDs of the PVS
  std::vector<uint32_t> objects;  // sorted indices of objects with a face in the PVS
  PvsStats stats;
};

class EpsilonPvs {
 public:
  // Prepares occluders, their kD-tree and per-face line pairs. The scene must
  // outlive this object. With `world` (the scene's static world, parts
  // Solids or more; used only while constructing), back faces are proved
  // over its triangles, solids and rays instead of a copy built here (the
  // same reading: the PVS contract's solids).
  explicit EpsilonPvs(const Scene& scene, const OccluderOptions& occluderOptions = {},
                      const StaticWorld* world = nullptr);
  ~EpsilonPvs();
  EpsilonPvs(const EpsilonPvs&) = delete;
  EpsilonPvs& operator=(const EpsilonPvs&) = delete;

  // `cell` in the scene's local frame.
  PvsResult compute(const Box3f& cell, const PvsOptions& options = {}) const;

  // The fused stage compute() runs last (PvsOptions::fusion): occlusion
  // horizons over the scene's solid columns (horizon_fusion.h), which hide
  // what several occluders hide together. Null: none. Not owned; it must
  // outlive this object's queries. Set it before any compute() runs.
  void setFusion(const HorizonFusion* fusion) { fusion_ = fusion; }
  const HorizonFusion* fusion() const { return fusion_; }

  // True if one occluder hides the whole closed box from every point of the
  // cell: the test compute() applies to object boxes (8 corner-to-corner
  // lines). For dynamic things such as avatars. Thread-safe like compute().
  bool boxHidden(const Box3f& cell, const Box3f& box) const;

  const OccluderSet& occluders() const { return occluders_; }
  // The distinct vertices of a face (local frame), or null for an unknown ID.
  const std::vector<glm::dvec3>* faceVertices(uint32_t faceId) const;
  const Scene& scene() const { return scene_; }
  double prepareMs() const { return prepareMs_; }

 public:
  struct Face;  // an occludee face: its vertices and the lines worth casting

 private:
  struct ObjectEntry;
  const Scene& scene_;
  OccluderSet occluders_;
  KdTree occluderTree_;
  std::vector<ObjectEntry> objects_;
  std::vector<std::pair<uint32_t, uint32_t>> faceIndex_;  // face ID -> (object entry, face), or ~0u
  std::vector<std::vector<uint32_t>> occludersOf_;        // scene object -> its occluders
  const HorizonFusion* fusion_ = nullptr;
  std::unique_ptr<PlanarFusion> planar_;  // over occluders_
  std::vector<float>
      solidFloor_;  // by solid behind one-sided faces: the height a viewpoint must exceed
  double prepareMs_ = 0.0;

  friend struct PvsQuery;
};

}  // namespace vistream
