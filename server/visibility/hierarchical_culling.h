// Hierarchical visibility culling over a kD-tree with occlusion trees, and
// the coherence methods of Bittner and Havran, "Exploiting coherence in
// hierarchical visibility algorithms" (J. Visual. Comput. Animat. 2001):
//   A  classical: test from the root every frame (section "Classical Approach");
//   B  hierarchy updating with pull-up (Figure 4): opened nodes of the last
//      frame are skipped, only termination nodes are tested;
//   C  B plus visibility propagation (section "Visibility Propagation"): a
//      node is classified from the neighbours across its front faces, found
//      through the kD-tree's ropes, before it would be tested; tried on nodes
//      not partially visible last frame, always where it succeeded last
//      frame and otherwise with probability p_vp;
//   D  C plus conservative hierarchy updating: a termination node that was
//      visible or partially visible is classified visible without a test with
//      probability p_skip;
//   adaptive  D with decisions learnt from the history of visibility changes
//      (the paper's future work): a visible node's test is skipped while the
//      expected cost of drawing it in vain (the chance that it turned less
//      visible since its last test, from its own rate of such changes per
//      frame and the rate over all nodes, times its faces' drawing cost) is
//      below the cost of a test; propagation is tried with the node's recent
//      rate of success.
//
// Order of the steps for a node (the paper's Figure 2): hierarchy updating,
// view-frustum culling, the small-node rule, visibility propagation,
// conservative skipping, the occlusion-tree test. The small-node rule comes
// before propagation so that C never culls a small node that A draws.
//
// Propagation uses only occlusion facts established in the current frame
// (an occlusion-tree answer, a propagated answer, or children's facts pulled
// up): "hidden" means every point of the box is in the shadow of the selected
// occluders, "lit" that none is. A node outside the view frustum, drawn by the
// small-node rule or skipped by D carries no fact. A node is hidden if every
// front face lies in a hidden neighbour; lit if every front face lies in a lit
// neighbour and no selected occluder reaches into its box. Both are exact
// consequences of the facts (the proof is in hierarchical_culling.cpp), so
// C's visible set is contained in A's, and equal to it except where the
// occlusion tree's test answers "partially visible" conservatively for a box
// that propagation proves hidden.
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
#include <mutex>
#include <random>
#include <string>
#include <vector>

#include "common/scene/scene.h"
#include "common/spatial/kdtree.h"
#include "server/visibility/occlusion_tree.h"

namespace vistream {

enum class CullingMethod : uint8_t {
  Classical,
  HierarchyUpdating,
  Propagation,
  Conservative,
  Adaptive
};

// Parses "A", "B", "C", "D" or "adaptive"; throws InputError otherwise.
CullingMethod parseCullingMethod(const std::string& name);
const char* cullingMethodName(CullingMethod m);

struct CullingOptions {
  CullingMethod method = CullingMethod::Classical;
  size_t occluders = 16;  // k best occluders per viewpoint
  double pSkip = 0.5;     // method D
  double pVp = 0.5;       // methods C and D
  uint64_t seed = 1;
  double fovDeg = 60.0;  // horizontal field of view
  double aspect = 4.0 / 3.0;
  // Small-node rule: a node with at most this many faces is cheaper to draw
  // than to test and is classified visible without a test.
  size_t smallNodeFaces = 8;
  bool collectFaces = false;  // fill FrameResult::faces
};

struct FrameResult {
  uint64_t nodeTests = 0;         // occlusion-tree node visibility tests
  uint64_t propagated = 0;        // nodes classified by visibility propagation
  uint64_t propagationTries = 0;  // propagation attempts, successful or not
  uint64_t skipped = 0;           // methods D and adaptive: tests skipped
  double cullingMs = 0.0;  // occluder selection, occlusion tree and traversal (not face gathering)
  size_t visibleLeaves = 0;  // visible or partially visible leaves
  size_t visibleFaces = 0;
  std::vector<uint32_t> faces;       // sorted, when CullingOptions::collectFaces
  std::vector<uint8_t> leafVisible;  // per kD-tree node: 1 for leaves drawn this frame
};

class CullingScene {
 public:
  explicit CullingScene(const Scene& scene);
  const Scene& scene() const { return scene_; }
  const KdTree& tree() const { return tree_; }
  const std::vector<OccluderPolygon>& occluderCandidates() const { return candidates_; }
  // Indices of the k best candidates for a viewpoint, best first: the ranking
  // of selectOccluders (solid angle estimate, edge-on polygons left out) from
  // data precomputed per candidate, without building shadow frusta.
  std::vector<size_t> bestOccluders(const glm::dvec3& viewpoint, size_t k) const;
  size_t nodeFaces(int32_t node) const { return nodeFaces_[size_t(node)]; }
  // The node's share of the faces: every object's faces split evenly among
  // the leaves holding it, summed over the subtree; what drawing the node
  // adds, on average, when the rest of the scene is drawn anyway (a floor
  // held by every leaf adds little to each).
  double faceShare(int32_t node) const { return faceShare_[size_t(node)]; }
  // Cost model of drawing: milliseconds per face, measured at construction
  // as the mean time to draw one of the scene's faces with a software
  // z-buffer rasterizer at 640x480 (this machine has no GPU; see
  // measureDrawMsPerFace in the .cpp for the views used).
  // Measured on first use (not at construction: a server that never asks
  // for frame times never pays for it). Thread-safe.
  double drawMsPerFace() const;

 private:
  const Scene& scene_;
  KdTree tree_;
  std::vector<OccluderPolygon> candidates_;
  struct CandidateShape {
    glm::dvec3 centroid, normal;
    double area;
  };
  std::vector<CandidateShape> shapes_;
  std::vector<size_t> nodeFaces_;
  std::vector<double> faceShare_;
  mutable std::once_flag drawCostOnce_;
  mutable double drawMsPerFace_ = 0.0;
};

class CullingViewer {
 public:
  CullingViewer(const CullingScene& scene, const CullingOptions& options);
  // Culls one frame from `eye` (local frame) looking along yaw/pitch.
  FrameResult frame(const glm::dvec3& eye, double yawDeg, double pitchDeg);

 private:
  // What the current frame established about a node's box and the shadow of
  // the selected occluders (valid while NodeState::frame is this frame).
  enum class Fact : uint8_t { Unknown, Hidden, Lit };
  struct NodeState {
    NodeVisibility visibility = NodeVisibility::PartiallyVisible;
    Fact fact = Fact::Unknown;
    int64_t frame = -10;
    int64_t propagatedFrame = -10;  // last frame propagation classified this node
    int64_t classifiedFrame = -10;  // last frame a test or propagation classified this node
    float changes = 0.0f,
          span = 0.0f;  // adaptive: decayed counts of turning less visible, and of frames
    float propagationRate = 0.5f;  // adaptive: recent rate of successful propagation
  };
  friend struct CullingFrame;  // one frame's steps (hierarchical_culling.cpp)
  Fact faceFact(int32_t node, KdFace face, const Box3f& faceBox) const;
  Fact subtreeFact(int32_t node, const Box3f& faceBox) const;

  const CullingScene& scene_;
  CullingOptions options_;
  std::vector<NodeState> state_;
  int64_t frame_ = 0;
  std::mt19937_64 rng_;
  double testMs_ = 0.0;                // adaptive: running estimate of one node test's cost
  double changes_ = 0.0, span_ = 0.0;  // adaptive: the same counts over all nodes (the prior)
};

}  // namespace vistream
