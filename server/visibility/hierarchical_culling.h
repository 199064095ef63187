// Hierarchical visibility culling over a kD-tree with occlusion trees, and
// the coherence methods of Bittner and Havran, "Exploiting coherence in
// hierarchical visibility algorithms" (J. Visual. Comput. Animat. 2001):
//   A  classical: test from the root every frame (section "Classical Approach");
//   B  hierarchy updating with pull-up (Figure 4): opened nodes of the last
//      frame are skipped, only termination nodes are tested;
//   D  B plus conservative hierarchy updating: a termination node that was
//      visible or partially visible is classified visible without a test with
//      probability p_skip.
// Visibility propagation through ropes (method C) and adaptive probabilities
// are not implemented yet.
//
// One CullingScene (kD-tree over objects, candidate occluder polygons, face
// counts) is shared read-only by any number of CullingViewer objects; each
// viewer keeps its own per-node state, so many clients keep their own
// coherence over one tree. A CullingViewer is not thread-safe; use one per
// thread or session.
//
// Conventions: the view frustum is 4:3, 60 degrees wide unless configured,
// orientation as in the path file format (yaw 0 looks along -Z, positive yaw
// turns left, positive pitch looks up). All positions in the scene's local frame.
#pragma once

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "common/scene/scene.h"
#include "common/spatial/kdtree.h"
#include "server/visibility/occlusion_tree.h"

namespace vistream {

enum class CullingMethod : uint8_t { Classical, HierarchyUpdating, Conservative };

// Parses "A", "B" or "D"; throws InputError otherwise.
CullingMethod parseCullingMethod(const std::string& name);
const char* cullingMethodName(CullingMethod m);

struct CullingOptions {
  CullingMethod method = CullingMethod::Classical;
  size_t occluders = 16;        // k best occluders per viewpoint
  double pSkip = 0.5;           // method D
  uint64_t seed = 1;
  double fovDeg = 60.0;         // horizontal field of view
  double aspect = 4.0 / 3.0;
  // Small-node rule: a node with at most this many faces is cheaper to draw
  // than to test and is classified visible without a test.
  size_t smallNodeFaces = 8;
  bool collectFaces = false;    // fill FrameResult::faces
};

struct FrameResult {
  uint64_t nodeTests = 0;        // occlusion-tree node visibility tests
  uint64_t propagated = 0;       // nodes classified by propagation (always 0 until method C exists)
  uint64_t skipped = 0;          // method D: tests skipped by p_skip
  double cullingMs = 0.0;        // occluder selection, occlusion tree and traversal (not face gathering)
  size_t visibleLeaves = 0;      // visible or partially visible leaves
  size_t visibleFaces = 0;
  std::vector<uint32_t> faces;   // sorted, when CullingOptions::collectFaces
  std::vector<uint8_t> leafVisible;  // per kD-tree node: 1 for leaves drawn this frame
};

class CullingScene {
 public:
  explicit CullingScene(const Scene& scene);
  const Scene& scene() const { return scene_; }
  const KdTree& tree() const { return tree_; }
  const std::vector<OccluderPolygon>& occluderCandidates() const { return candidates_; }
  size_t nodeFaces(int32_t node) const { return nodeFaces_[size_t(node)]; }
  // Cost model of drawing: milliseconds per face, measured at construction as
  // the time to transform one face's vertices and bound it on screen in
  // software (this machine has no GPU).
  double drawMsPerFace() const { return drawMsPerFace_; }

 private:
  const Scene& scene_;
  KdTree tree_;
  std::vector<OccluderPolygon> candidates_;
  std::vector<size_t> nodeFaces_;
  double drawMsPerFace_ = 0.0;
};

class CullingViewer {
 public:
  CullingViewer(const CullingScene& scene, const CullingOptions& options);
  // Culls one frame from `eye` (local frame) looking along yaw/pitch.
  FrameResult frame(const glm::dvec3& eye, double yawDeg, double pitchDeg);

 private:
  struct NodeState {
    NodeVisibility visibility = NodeVisibility::PartiallyVisible;
    int64_t frame = -10;
  };
  const CullingScene& scene_;
  CullingOptions options_;
  std::vector<NodeState> state_;
  int64_t frame_ = 0;
  std::mt19937_64 rng_;
};

}  // namespace vistream
