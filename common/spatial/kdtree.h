// kD-tree over the scene, with ropes, for hierarchical visibility culling and
// ray queries.
//
// A KdTree partitions the box of a set of items (objects' bounding boxes or
// triangles) with axis-aligned planes at arbitrary positions chosen by the
// surface area heuristic. Every node keeps its box; leaves list the items that
// overlap their box. After the build every node gets six ropes (Bittner and
// Havran 2001, "Exploiting coherence in hierarchical visibility algorithms",
// section "Visibility Propagation"): per face of its box, the smallest node on
// the other side of the face whose box contains that whole face.
//
// Coordinates: whatever frame the item boxes are in (for scenes, the local
// frame relative to Scene::origin, metres). Boxes are closed.
//
// Which items a leaf holds: every item that reaches into the open interior
// of the leaf box (judged by the item's box, or with split clipping by the
// box of its part inside the node), and for every point of an item at least
// one leaf whose closed box contains the point holds the item. An item lying
// exactly in a splitting plane, or touching it from one side only, may be
// held by the leaves on one side of the plane only; queries that must not
// miss such items (a ray through the plane) visit both sides, see
// traverseRay. Leaves may also hold items that merely touch their box.
//
// Memory: about 84 bytes a node (KdNode plus an 8-byte traversal copy) and 4
// bytes an item reference. A random triangle soup gives 2.5 to 5 nodes per
// triangle, so a 2M-triangle tree takes 0.5 to 1 GB.
//
// Bad input: items with an empty box (lo > hi on some axis) or a non-finite
// coordinate are in no leaf; they are counted in KdStats::skippedItems. Item
// indices in leaves are indices into the span given to build().
//
// Thread safety: a built KdTree is immutable; all const members may be called
// concurrently. build() uses TBB for large inputs when options.parallel is set.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <glm/glm.hpp>
#include <limits>
#include <span>
#include <type_traits>
#include <vector>

#include "common/core/box.h"
#include "common/scene/scene.h"

namespace vistream {

// Faces of a node's box, in rope order: 2 * axis + (1 for the high side).
enum KdFace : int { kNegX = 0, kPosX = 1, kNegY = 2, kPosY = 3, kNegZ = 4, kPosZ = 5 };
inline constexpr int kdFace(int axis, bool highSide) {
  return 2 * axis + (highSide ? 1 : 0);
}

// Build parameters. The cost model is Havran's (PhD thesis, 2000): splitting
// a node costs traversalCost + intersectionCost * (P_below * N_below +
// P_above * N_above) with P the surface area ratio child / node (times
// 1 - emptyBonus when a child is empty), a leaf costs intersectionCost * N,
// and a node is split only when that is strictly cheaper.
//
// The defaults are for culling over objects: the empty bonus cuts empty
// space off, which gives tighter boxes to cull, and the interior generator
// (common/generate/interior.cpp) is calibrated against the node counts they
// give. For ray casting against triangles, kRayCastingKdOptions halves the
// node count (2.5 instead of 4.6 nodes per triangle on random soups of 200k
// triangles) at the same rays per second.
struct KdBuildOptions {
  int maxDepth = 0;               // 0: automatic, 8 + 1.3 log2(items) (pbrt-v3), at most kMaxDepth
  uint32_t leafItems = 2;         // a node with at most this many items is a leaf, never split
  float traversalCost = 1.0f;     // cost of visiting one interior node
  float intersectionCost = 1.5f;  // cost of testing one item
  float emptyBonus = 0.2f;        // in [0, 1)
  bool parallel = true;           // build large subtrees in parallel with TBB
};

// What makeKdTreeRayQuery builds with (tuned as said above).
inline constexpr KdBuildOptions kRayCastingKdOptions{.maxDepth = 0,
                                                     .leafItems = 2,
                                                     .traversalCost = 1.0f,
                                                     .intersectionCost = 1.0f,
                                                     .emptyBonus = 0.0f,
                                                     .parallel = true};

// Bounds of the part of item `item` that lies inside the closed box `box`, or
// an empty box when no part does. Must be conservative (every point of the
// item inside `box` is inside the result) and safe to call concurrently.
using KdItemClipper = std::function<Box3f(uint32_t item, const Box3f& box)>;

// Bounds of the part of triangle abc inside the closed box `box` (Sutherland-
// Hodgman clipping in double precision, rounded outward to float), or an empty
// box. Degenerate triangles clip like any other point set.
Box3f clippedTriangleBounds(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                            const Box3f& box);

struct KdNode {
  Box3f box;
  int32_t parent = -1;                      // -1 for the root
  std::array<int32_t, 2> children{-1, -1};  // below and above the split plane; -1 for leaves
  std::array<int32_t, 6> ropes{-1, -1, -1, -1, -1, -1};  // per KdFace; -1 on the scene boundary
  float split = 0.0f;                     // plane position on `axis` (interior nodes)
  int8_t axis = -1;                       // 0, 1, 2; -1 for leaves
  uint16_t depth = 0;                     // root is 0
  uint32_t firstItem = 0, itemCount = 0;  // leaves: range in the shared item index array

  bool isLeaf() const { return axis < 0; }
};

struct KdStats {
  size_t items = 0;         // items given to build()
  size_t skippedItems = 0;  // of those, with an empty or non-finite box
  size_t nodes = 0;
  size_t leaves = 0;
  size_t emptyLeaves = 0;
  int maxDepth = 0;
  size_t itemReferences = 0;    // sum over leaves of their item counts
  double meanItemsPerLeaf = 0;  // itemReferences / leaves, empty leaves included
  double buildMs = 0;           // wall clock of build(), ropes included
};

class KdTree {
 public:
  static constexpr int kMaxDepth = 60;

  // An empty tree: one empty leaf with an empty box.
  KdTree();

  // Builds over items given by their bounds. With `clipItem`, items that
  // straddle a splitting plane are clipped to each child's box ("split
  // clipping"), so leaves hold only items that really reach into them;
  // without, straddling items keep their box cut by the plane.
  static KdTree build(std::span<const Box3f> itemBounds, const KdBuildOptions& options = {},
                      const KdItemClipper& clipItem = {});
  // Items are scene.objects (by index), with their bounding boxes.
  static KdTree buildOverObjects(const Scene& scene, const KdBuildOptions& options = {});
  // Items are the triangles of `triangles` (by index), with split clipping.
  // Degenerate triangles are items like any other.
  static KdTree buildOverTriangles(const FlatTriangles& triangles,
                                   const KdBuildOptions& options = {});

  static constexpr int32_t root() { return 0; }
  const std::vector<KdNode>& nodes() const { return nodes_; }
  const KdNode& node(int32_t index) const { return nodes_[size_t(index)]; }
  const Box3f& bounds() const { return nodes_.front().box; }
  // Items of a leaf, ascending; empty for interior nodes.
  std::span<const uint32_t> items(int32_t node) const {
    const TraversalNode& n = traversal_[size_t(node)];
    if ((n.bits & 3u) != kLeafBits) return {};
    return std::span<const uint32_t>(itemIndices_).subspan(n.bits >> 2, n.itemCount);
  }
  // The neighbour across `face` of `node` (see the file comment), or -1.
  int32_t rope(int32_t node, KdFace face) const { return nodes_[size_t(node)].ropes[face]; }
  // A leaf whose closed box contains p (the one below the plane when p lies on
  // a split plane), or -1 when p is outside the tree's bounds.
  int32_t leafContaining(const glm::vec3& p) const;

  KdStats stats() const { return stats_; }

  // Visits the leaves that the ray segment org + t*dir, t in [tnear, tfar],
  // passes through, front to back: entering the near child of each node first,
  // so tEnter is nondecreasing from one leaf to the next. Plane crossings are
  // widened by a relative 1e-6 so that a segment passing exactly through an
  // edge or corner of a leaf visits every leaf that touches it; a segment lying
  // in a splitting plane visits both sides (below first, then above, so there
  // the order in t restarts). The callback is
  //   visitLeaf(int32_t leaf, float tEnter, float tExit) -> bool or float:
  // bool: false stops the traversal; float: the new end of the segment, and
  // nodes entered beyond it are skipped (return the nearest hit so far, with a
  // margin, or -infinity to stop).
  template <class F>
  void traverseRay(const glm::vec3& org, const glm::vec3& dir, float tnear, float tfar,
                   F&& visitLeaf) const;

  // Visits nodes in front-to-back order from `viewpoint` (a depth-first walk
  // taking the child on the viewpoint's side of the split first; ties at the
  // plane take the child below). visit(int32_t node) -> bool says whether to
  // descend into that node's children; it is ignored for leaves. Every node a
  // visited node may occlude is visited after it.
  template <class F>
  void traverseFrontToBack(const glm::vec3& viewpoint, F&& visit) const;

 private:
  // The tree again for ray traversal, 8 bytes a node instead of KdNode's 80,
  // so that a ray touches few cache lines. Same indices as nodes_; nodes are
  // laid out depth first, so an interior node's lower child is the next node.
  struct TraversalNode {
    uint32_t bits;  // low 2 bits: axis, or 3 for a leaf; above them: the upper child
                    // (interior) or the first item (leaf)
    union {
      float split;         // interior
      uint32_t itemCount;  // leaf
    };
  };
  static constexpr uint32_t kLeafBits = 3;

  std::vector<KdNode> nodes_;
  std::vector<TraversalNode> traversal_;
  std::vector<uint32_t> itemIndices_;
  KdStats stats_;

  void finishBuild();  // ropes, traversal nodes, statistics
  void computeRopes();
  void computeStats();
};

// ---- traversal templates -----------------------------------------------------

template <class F>
void KdTree::traverseRay(const glm::vec3& org, const glm::vec3& dir, float tnear, float tfar,
                         F&& visitLeaf) const {
  // Plane crossings t = (p - o) / d are correctly rounded quotients of exact
  // differences of floats, so each carries a relative error below 1.2e-7;
  // widening by 1e-6 of the magnitudes involved covers comparing two of them.
  constexpr float kWiden = 1e-6f;
  const Box3f& rootBox = nodes_.front().box;
  if (rootBox.empty() || dir == glm::vec3(0.0f)) return;
  float t0 = tnear, t1 = tfar;
  for (int a = 0; a < 3; ++a) {
    if (dir[a] == 0.0f) {
      if (org[a] < rootBox.lo[a] || org[a] > rootBox.hi[a]) return;
      continue;
    }
    float ta = (rootBox.lo[a] - org[a]) / dir[a], tb = (rootBox.hi[a] - org[a]) / dir[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta - kWiden * std::abs(ta));
    t1 = std::min(t1, tb + kWiden * std::abs(tb));
  }
  if (!(t0 <= t1)) return;

  struct Entry {
    int32_t node;
    float tmin, tmax;
  };
  std::array<Entry, kMaxDepth + 4> stack;
  int top = 0;
  stack[size_t(top++)] = Entry{root(), t0, t1};
  while (top > 0) {
    Entry e = stack[size_t(--top)];
    if (e.tmin > t1) continue;  // starts beyond the (possibly shortened) segment
    for (;;) {
      const TraversalNode n = traversal_[size_t(e.node)];
      const uint32_t a = n.bits & 3u;
      if (a == kLeafBits) break;
      const float p = n.split;
      const int32_t below = e.node + 1, above = int32_t(n.bits >> 2);
      if (dir[a] == 0.0f) {
        if (org[a] < p) {
          e.node = below;
        } else if (org[a] > p) {
          e.node = above;
        } else {  // in the plane: items touching it from either side may be hit
          stack[size_t(top++)] = Entry{above, e.tmin, e.tmax};
          e.node = below;
        }
        continue;
      }
      // The child the line is in before it crosses the plane (at ts) comes
      // first; that is the origin's side only when ts >= 0.
      const bool belowFirst = dir[a] > 0.0f;
      const int32_t nearChild = belowFirst ? below : above;
      const int32_t farChild = belowFirst ? above : below;
      const float ts = (p - org[a]) / dir[a];
      const bool visitNear = ts >= e.tmin - kWiden * (std::abs(ts) + std::abs(e.tmin));
      const bool visitFar = ts <= e.tmax + kWiden * (std::abs(ts) + std::abs(e.tmax)) &&
                            ts <= t1 + kWiden * (std::abs(ts) + std::abs(t1));
      const float tsClamped = std::min(std::max(ts, e.tmin), e.tmax);
      if (visitNear && visitFar) {
        stack[size_t(top++)] = Entry{farChild, tsClamped, e.tmax};
        e.node = nearChild;
        e.tmax = tsClamped;
      } else if (visitNear) {
        e.node = nearChild;
      } else {
        e.node = farChild;
      }
    }
    using Result = std::invoke_result_t<F&, int32_t, float, float>;
    if constexpr (std::is_same_v<Result, bool>) {
      if (!visitLeaf(e.node, e.tmin, e.tmax)) return;
    } else {
      static_assert(std::is_convertible_v<Result, float>,
                    "visitLeaf must return bool (go on) or float (new segment end)");
      t1 = std::min(t1, float(visitLeaf(e.node, e.tmin, e.tmax)));
    }
  }
}

template <class F>
void KdTree::traverseFrontToBack(const glm::vec3& viewpoint, F&& visit) const {
  std::array<int32_t, kMaxDepth + 4> stack;
  int top = 0;
  stack[size_t(top++)] = root();
  while (top > 0) {
    const int32_t index = stack[size_t(--top)];
    const bool descend = visit(index);
    const KdNode& n = nodes_[size_t(index)];
    if (!descend || n.isLeaf()) continue;
    const bool belowFirst = viewpoint[n.axis] <= n.split;
    stack[size_t(top++)] = n.children[belowFirst ? 1 : 0];
    stack[size_t(top++)] = n.children[belowFirst ? 0 : 1];
  }
}

}  // namespace vistream
