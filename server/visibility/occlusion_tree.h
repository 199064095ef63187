// Occlusion tree: the fused shadow of a few large polygonal occluders as seen
// from one viewpoint, stored as a BSP tree whose leaves are 'in' (occluded) or
// 'out' (unoccluded), and the node visibility test on it (Bittner, Havran and
// Slavik 1998, "Hierarchical visibility culling with occlusion trees", as
// summarised in section 2 of Bittner and Havran 2001, "Exploiting coherence in
// hierarchical visibility algorithms").
//
// Conventions: the scene's local frame, double precision, Y up, metres. The
// viewer sees in all directions (no view frustum).
//
// Shadow: a point p is in shadow when the segment from the viewpoint to p
// crosses the interior of the union of the occluder polygons (so a segment
// through the shared edge of two adjacent occluders is blocked: occluder
// fusion). Points on a shadow boundary are not in shadow.
//
// Bad input: occluders with fewer than 3 vertices, zero area or collinear
// vertices are ignored, and so is every occluder whose plane passes within the
// rounding tolerance of the viewpoint (it is seen edge-on and casts no shadow;
// this also covers a viewpoint on an occluder's edge). Non-convex or non-planar
// polygons are not detected: they produce a shadow that need not match the
// polygon, but never a crash.
//
// Rounding: every test treats a point within a tolerance of 1e-9 * (1 + the
// largest coordinate magnitude involved) of a plane as lying on it, and every
// answer errs towards "visible": a box that comes that close to a shadow
// boundary is PartiallyVisible. Occluders that pass within that tolerance of
// the viewpoint are ignored, so a box inside such an occluder's sliver of
// shadow may be reported Visible.
//
// Thread safety: a built tree is immutable; concurrent const calls are safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <glm/glm.hpp>
#include <span>
#include <vector>

#include "common/core/box.h"

namespace vistream {

enum class NodeVisibility : uint8_t { Invisible, PartiallyVisible, Visible };

// A convex planar polygon, vertices in order (either winding), local frame.
struct OccluderPolygon {
  std::vector<glm::dvec3> vertices;
};

// The indices of the (at most) k best occluders for a viewpoint, best first,
// ranked by the solid angle they subtend, estimated as
//   area * |cos(angle between the polygon normal and the view vector)| / distance^2
// with the view vector and distance taken from the viewpoint to the polygon's
// vertex centroid. Degenerate polygons and polygons whose plane passes within
// the rounding tolerance of the viewpoint are never returned (they cast no
// shadow), so fewer than k indices come back when fewer remain. Equal scores
// keep their input order.
std::vector<size_t> selectOccluders(const glm::dvec3& viewpoint,
                                    std::span<const OccluderPolygon> candidates, size_t k);

class OcclusionTree {
 public:
  // Builds the tree by inserting the occluders one by one, in the given order
  // (the classic occlusion-tree insertion: a polygon is split by the node
  // planes it meets; a fragment reaching an 'out' leaf replaces it with the
  // fragment's shadow frustum, a fragment reaching an 'in' leaf is already
  // hidden and dropped). Passing the occluders best first, as selectOccluders
  // orders them, keeps the tree small. The polygons are copied; the span need
  // not outlive the tree.
  OcclusionTree(const glm::dvec3& viewpoint, std::span<const OccluderPolygon> occluders);

  // Conservative visibility of the closed box from the viewpoint:
  //  - Invisible: every point of the box is in shadow;
  //  - Visible: no point of the box is in shadow;
  //  - PartiallyVisible: otherwise, or when the test cannot tell.
  // Invisible and Visible are never wrong; PartiallyVisible is the
  // conservative answer for a box within the tolerance of a shadow boundary.
  // Otherwise the answer is exact: the search tests the box against one
  // plane at a time, and a leaf reached past two or more planes the box
  // straddles counts only if the box really meets the leaf's cell, so trees
  // of the same shadow built differently give the same answers.
  // A box containing or touching the viewpoint is never Invisible. An empty
  // box is Visible. The constrained depth-first search enters only the
  // half-spaces the box reaches and stops as soon as it has reached both an
  // 'in' and an 'out' leaf. If nodesVisited is given, the number of tree
  // nodes the search visited (interior nodes and leaves) is added to it.
  NodeVisibility classify(const Box3f& box, uint64_t* nodesVisited = nullptr) const;

  // True if p is in shadow by more than the rounding tolerance (a point on or
  // near a shadow boundary is not).
  bool inShadow(const glm::dvec3& p) const;

  // Nodes of the BSP tree, interior nodes and leaves; 1 for an empty tree.
  size_t nodeCount() const { return 2 * nodes_.size() + 1; }
  // Occluders that were usable (not ignored as degenerate or edge-on); an
  // occluder that ended up entirely hidden by earlier ones still counts.
  size_t occluderCount() const { return occluderCount_; }
  const glm::dvec3& viewpoint() const { return viewpoint_; }

 private:
  // Child links: a node index, or one of the two leaf kinds.
  static constexpr int32_t kOutLeaf = -1;
  static constexpr int32_t kInLeaf = -2;

  // A plane dot(normal, x - viewpoint) = offset with unit normal; 'front' is
  // the side where dot(normal, x - viewpoint) > offset.
  struct Node {
    glm::dvec3 normal{0.0};
    double offset = 0.0;
    int32_t front = kOutLeaf;
    int32_t back = kOutLeaf;
  };

  NodeVisibility classifyRelative(const glm::dvec3& lo, const glm::dvec3& hi, double tolerance,
                                  uint64_t* nodesVisited) const;

  glm::dvec3 viewpoint_{0.0};
  double magnitude_ = 0.0;  // largest coordinate magnitude of the viewpoint and occluders
  std::vector<Node> nodes_;
  int32_t root_ = kOutLeaf;
  size_t occluderCount_ = 0;
};

}  // namespace vistream
