// kD-tree build, ropes and statistics.
//
// The tree is the spatial hierarchy of Bittner and Havran 2001, "Exploiting
// coherence in hierarchical visibility algorithms" (section "Spatial
// Hierarchy": a kD-tree with arbitrarily placed planes whose leaves list the
// objects intersecting their box). Splits follow the surface area heuristic
// as in Havran, "Heuristic Ray Shooting Algorithms", PhD thesis, CTU Prague
// 2000: candidate planes are the item box boundaries on all three axes,
// evaluated by a sweep over sorted boundaries, so each node costs O(n log n)
// (here O(n) with a radix sort) and the build O(n log^2 n). Items lying in a
// candidate plane are counted on whichever side is cheaper, and straddling
// items are clipped to the child boxes ("perfect splits"), both as in Wald and
// Havran, "On building fast kd-Trees for Ray Tracing, and on doing that in
// O(N log N)", IEEE RT 2006.
//
// Ropes follow Bittner and Havran 2001, section "Visibility Propagation" and
// Figure 6, after Havran, Bittner and Zara 1998, "Ray tracing with rope
// trees": each face of a node links to the smallest node on the other side
// that contains the whole face. They are pushed down from parents to children
// and then moved down the neighbour's subtree while a child still contains
// the face.
#include "common/spatial/kdtree.h"

#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <memory>
#include <utility>

#include "common/core/check.h"
#include "common/core/timer.h"

namespace vistream {

namespace {

// Subtrees with at least this many item references are built as separate
// TBB tasks and their splits evaluate the three axes in parallel. A 1M-
// triangle build then makes a few hundred tasks, enough to keep a handful of
// cores busy; not tuned further.
constexpr size_t kParallelItems = 16384;
// Below this many keys std::sort beats the radix sort's fixed passes.
constexpr size_t kRadixSortMin = 128;

struct ItemRef {
  uint32_t item;
  Box3f box;  // the item's part inside the node, conservative
};

// Floats mapped to unsigned keys with the same order, so that equal
// positions compare equal and sorting is integer sorting. -0 is folded into +0.
uint32_t orderKey(float f) {
  const uint32_t bits = std::bit_cast<uint32_t>(f + 0.0f);
  return (bits & 0x80000000u) ? ~bits : (bits | 0x80000000u);
}
float keyValue(uint32_t key) {
  const uint32_t bits = (key & 0x80000000u) ? (key & 0x7fffffffu) : ~key;
  return std::bit_cast<float>(bits);
}

// LSD radix sort by bytes. Keys of one node share their high bytes (its items
// lie in a small range of floats), so passes where every key falls in one
// bucket are skipped; deep nodes usually need two passes.
void sortKeys(std::vector<uint32_t>& keys, std::vector<uint32_t>& scratch) {
  const size_t n = keys.size();
  if (n < kRadixSortMin) {
    std::sort(keys.begin(), keys.end());
    return;
  }
  std::array<std::array<uint32_t, 256>, 4> count{};
  for (const uint32_t k : keys) {
    ++count[0][k & 0xffu];
    ++count[1][(k >> 8) & 0xffu];
    ++count[2][(k >> 16) & 0xffu];
    ++count[3][k >> 24];
  }
  scratch.resize(n);
  for (int pass = 0; pass < 4; ++pass) {
    auto& c = count[size_t(pass)];
    const int shift = pass * 8;
    if (c[(keys[0] >> shift) & 0xffu] == n) continue;  // one bucket: already in order
    uint32_t sum = 0;
    for (uint32_t& bucket : c) {
      const uint32_t here = bucket;
      bucket = sum;
      sum += here;
    }
    for (const uint32_t k : keys) scratch[c[(k >> shift) & 0xffu]++] = k;
    keys.swap(scratch);
  }
}

struct AxisScratch {
  std::vector<uint32_t> lo, hi, planar, tmp;
};
struct Scratch {
  std::array<AxisScratch, 3> axes;
};

struct SplitChoice {
  int axis = -1;
  float position = 0.0f;
  bool planarBelow = false;  // items lying in the plane go below (else above)
  float cost = std::numeric_limits<float>::infinity();
};

// Nodes as the builder makes them. Subtrees built by parallel tasks are
// separate chunks, linked from their parent's chunk, so nothing is copied
// until the final depth-first layout.
struct Subtree {
  std::vector<KdNode> nodes;  // children: index in `nodes`, or kExternal - slot
  std::vector<uint32_t> items;
  struct External {
    std::unique_ptr<Subtree> chunk;
    int32_t root;
  };
  std::vector<External> externals;
};
constexpr int32_t kExternal = -2;  // child index kExternal - k: root of externals[k]
constexpr int32_t kUnset = std::numeric_limits<int32_t>::min();

class KdBuilder {
 public:
  KdBuilder(const KdBuildOptions& options, const KdItemClipper& clip, int maxDepth)
      : options_(options), clip_(clip), maxDepth_(maxDepth) {}

  // Appends the subtree over `refs` (all inside `box`) to `out` and returns
  // the index of its root there. Children come after their parent.
  int32_t build(Subtree& out, std::vector<ItemRef>&& refs, const Box3f& box, int depth,
                Scratch& scratch) const;

 private:
  const KdBuildOptions& options_;
  const KdItemClipper& clip_;
  int maxDepth_;

  SplitChoice findSplit(const std::vector<ItemRef>& refs, const Box3f& box, Scratch& scratch) const;
  void sweepAxis(const std::vector<ItemRef>& refs, const Box3f& box, int axis, AxisScratch& scratch,
                 SplitChoice& best) const;
  void partition(std::vector<ItemRef>& refs, const SplitChoice& split, const Box3f& below,
                 const Box3f& above, std::vector<ItemRef>& refsBelow,
                 std::vector<ItemRef>& refsAbove) const;
};

void KdBuilder::sweepAxis(const std::vector<ItemRef>& refs, const Box3f& box, int axis,
                          AxisScratch& s, SplitChoice& best) const {
  s.lo.clear();
  s.hi.clear();
  s.planar.clear();
  for (const ItemRef& r : refs) {
    if (r.box.lo[axis] == r.box.hi[axis]) {
      s.planar.push_back(orderKey(r.box.lo[axis]));
    } else {
      s.lo.push_back(orderKey(r.box.lo[axis]));
      s.hi.push_back(orderKey(r.box.hi[axis]));
    }
  }
  sortKeys(s.lo, s.tmp);
  sortKeys(s.hi, s.tmp);
  sortKeys(s.planar, s.tmp);

  const glm::vec3 extent = box.hi - box.lo;
  const int b = (axis + 1) % 3, c = (axis + 2) % 3;
  const float crossArea = extent[b] * extent[c], crossPerimeter = extent[b] + extent[c];
  const float invArea = 1.0f / box.surfaceArea();
  const float ct = options_.traversalCost, ci = options_.intersectionCost;
  const float bonus = 1.0f - options_.emptyBonus;
  auto cost = [&](float areaBelow, float areaAbove, size_t nBelow, size_t nAbove) {
    const float c0 = ct + ci * (areaBelow * float(nBelow) + areaAbove * float(nAbove)) * invArea;
    return (nBelow == 0 || nAbove == 0) ? c0 * bonus : c0;
  };

  const size_t nLo = s.lo.size(), nHi = s.hi.size(), nPlanar = s.planar.size();
  constexpr uint32_t kEnd = 0xffffffffu;  // above every key of a finite float
  size_t i = 0, j = 0, k = 0;
  while (i < nLo || j < nHi || k < nPlanar) {
    const uint32_t key = std::min(
        {i < nLo ? s.lo[i] : kEnd, j < nHi ? s.hi[j] : kEnd, k < nPlanar ? s.planar[k] : kEnd});
    const size_t startsBefore = i, planarBefore = k;
    while (i < nLo && s.lo[i] == key) ++i;
    while (j < nHi && s.hi[j] == key) ++j;
    while (k < nPlanar && s.planar[k] == key) ++k;
    const float p = keyValue(key);
    // Only planes strictly inside the box: both children are then strictly
    // smaller, which bounds the recursion even without the depth limit.
    if (!(p > box.lo[axis] && p < box.hi[axis])) continue;
    const size_t below = startsBefore + planarBefore;  // items reaching below p
    const size_t above = (nHi - j) + (nPlanar - k);    // items reaching above p
    const size_t inPlane = k - planarBefore;
    const float areaBelow = 2.0f * (crossArea + (p - box.lo[axis]) * crossPerimeter);
    const float areaAbove = 2.0f * (crossArea + (box.hi[axis] - p) * crossPerimeter);
    const float costBelow = cost(areaBelow, areaAbove, below + inPlane, above);
    const float costAbove = cost(areaBelow, areaAbove, below, above + inPlane);
    const bool planarBelow = costBelow <= costAbove;
    const float c0 = planarBelow ? costBelow : costAbove;
    if (c0 < best.cost) best = SplitChoice{axis, p, planarBelow, c0};
  }
}

SplitChoice KdBuilder::findSplit(const std::vector<ItemRef>& refs, const Box3f& box,
                                 Scratch& scratch) const {
  if (refs.size() > kParallelItems && options_.parallel) {
    std::array<SplitChoice, 3> perAxis;
    auto axisTask = [&](int a) {
      if (box.lo[a] < box.hi[a])
        sweepAxis(refs, box, a, scratch.axes[size_t(a)], perAxis[size_t(a)]);
    };
    tbb::parallel_invoke([&] { axisTask(0); }, [&] { axisTask(1); }, [&] { axisTask(2); });
    SplitChoice best;
    for (const SplitChoice& s : perAxis)  // first axis wins ties, as in the serial loop
      if (s.cost < best.cost) best = s;
    return best;
  }
  SplitChoice best;
  for (int a = 0; a < 3; ++a)
    if (box.lo[a] < box.hi[a]) sweepAxis(refs, box, a, scratch.axes[0], best);
  return best;
}

void KdBuilder::partition(std::vector<ItemRef>& refs, const SplitChoice& split, const Box3f& below,
                          const Box3f& above, std::vector<ItemRef>& refsBelow,
                          std::vector<ItemRef>& refsAbove) const {
  const int a = split.axis;
  const float p = split.position;
  for (const ItemRef& r : refs) {
    const float lo = r.box.lo[a], hi = r.box.hi[a];
    if (lo == p && hi == p) {
      (split.planarBelow ? refsBelow : refsAbove).push_back(r);
    } else if (hi <= p) {
      refsBelow.push_back(r);
    } else if (lo >= p) {
      refsAbove.push_back(r);
    } else if (clip_) {
      // Both clips stay inside r.box (the item's part in this node), which
      // keeps float rounding of the two clips from growing the part.
      const Box3f partBelow = clip_(r.item, below).intersection(r.box);
      const Box3f partAbove = clip_(r.item, above).intersection(r.box);
      if (!partBelow.empty()) refsBelow.push_back(ItemRef{r.item, partBelow});
      if (!partAbove.empty()) refsAbove.push_back(ItemRef{r.item, partAbove});
    } else {
      ItemRef partBelow = r, partAbove = r;
      partBelow.box.hi[a] = p;
      partAbove.box.lo[a] = p;
      refsBelow.push_back(partBelow);
      refsAbove.push_back(partAbove);
    }
  }
}

int32_t KdBuilder::build(Subtree& out, std::vector<ItemRef>&& refs, const Box3f& box, int depth,
                         Scratch& scratch) const {
  const auto index = int32_t(out.nodes.size());
  {
    KdNode node;
    node.box = box;
    node.depth = uint16_t(depth);
    out.nodes.push_back(node);
  }

  SplitChoice split;
  if (refs.size() > options_.leafItems && depth < maxDepth_ && box.surfaceArea() > 0.0f) {
    split = findSplit(refs, box, scratch);
    if (!(split.cost < options_.intersectionCost * float(refs.size()))) split.axis = -1;
  }
  if (split.axis < 0) {
    KdNode& leaf = out.nodes[size_t(index)];
    leaf.firstItem = uint32_t(out.items.size());
    leaf.itemCount = uint32_t(refs.size());
    for (const ItemRef& r : refs) out.items.push_back(r.item);
    std::sort(out.items.begin() + leaf.firstItem, out.items.end());
    return index;
  }

  Box3f below = box, above = box;
  below.hi[split.axis] = split.position;
  above.lo[split.axis] = split.position;
  std::vector<ItemRef> refsBelow, refsAbove;
  refsBelow.reserve(refs.size() / 2 + 1);
  refsAbove.reserve(refs.size() / 2 + 1);
  partition(refs, split, below, above, refsBelow, refsAbove);
  const size_t total = refs.size();
  std::vector<ItemRef>().swap(refs);  // the children own the references now

  {
    KdNode& n = out.nodes[size_t(index)];
    n.axis = int8_t(split.axis);
    n.split = split.position;
  }
  int32_t childBelow = -1, childAbove = -1;
  if (options_.parallel && total >= kParallelItems) {
    auto subBelow = std::make_unique<Subtree>(), subAbove = std::make_unique<Subtree>();
    int32_t rootBelow = -1, rootAbove = -1;
    tbb::parallel_invoke(
        [&] {
          Scratch own;
          rootBelow = build(*subBelow, std::move(refsBelow), below, depth + 1, own);
        },
        [&] {
          Scratch own;
          rootAbove = build(*subAbove, std::move(refsAbove), above, depth + 1, own);
        });
    childBelow = kExternal - int32_t(out.externals.size());
    out.externals.push_back({std::move(subBelow), rootBelow});
    childAbove = kExternal - int32_t(out.externals.size());
    out.externals.push_back({std::move(subAbove), rootAbove});
  } else {
    childBelow = build(out, std::move(refsBelow), below, depth + 1, scratch);
    childAbove = build(out, std::move(refsAbove), above, depth + 1, scratch);
  }
  out.nodes[size_t(index)].children = {childBelow, childAbove};
  return index;
}

void countChunk(const Subtree& chunk, size_t& nodes, size_t& items) {
  nodes += chunk.nodes.size();
  items += chunk.items.size();
  for (const Subtree::External& e : chunk.externals) countChunk(*e.chunk, nodes, items);
}

bool isUsableBox(const Box3f& b) {
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(b.lo[a]) || !std::isfinite(b.hi[a]) || b.lo[a] > b.hi[a]) return false;
  return true;
}

// Rounds a double to the float at or below (or above) it, so that float boxes
// built from double coordinates still enclose them.
float floatAtOrBelow(double d) {
  float f = float(d);
  if (double(f) > d) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
  return f;
}
float floatAtOrAbove(double d) {
  float f = float(d);
  if (double(f) < d) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

}  // namespace

Box3f clippedTriangleBounds(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                            const Box3f& box) {
  Box3f triangleBox;
  triangleBox.extend(a);
  triangleBox.extend(b);
  triangleBox.extend(c);
  if (!triangleBox.overlaps(box)) return Box3f{};
  if (box.contains(triangleBox.lo) && box.contains(triangleBox.hi)) return triangleBox;

  // Sutherland-Hodgman against the six planes; a convex polygon clipped by 6
  // planes has at most 3 + 6 vertices. Vertices on a plane count as inside.
  std::array<std::array<glm::dvec3, 12>, 2> poly;
  int count = 3, cur = 0;
  poly[0][0] = glm::dvec3(a);
  poly[0][1] = glm::dvec3(b);
  poly[0][2] = glm::dvec3(c);
  for (int axis = 0; axis < 3 && count > 0; ++axis) {
    for (int side = 0; side < 2 && count > 0; ++side) {
      // A plane the triangle lies wholly inside of cuts nothing off.
      if (side == 0 ? triangleBox.lo[axis] >= box.lo[axis] : triangleBox.hi[axis] <= box.hi[axis])
        continue;
      const double plane = side == 0 ? box.lo[axis] : box.hi[axis];
      auto inside = [&](const glm::dvec3& v) {
        return side == 0 ? v[axis] >= plane : v[axis] <= plane;
      };
      const auto& src = poly[size_t(cur)];
      auto& dst = poly[size_t(1 - cur)];
      int n = 0;
      for (int i = 0; i < count; ++i) {
        const glm::dvec3& p = src[size_t(i)];
        const glm::dvec3& q = src[size_t((i + 1) % count)];
        const bool pIn = inside(p), qIn = inside(q);
        if (pIn) dst[size_t(n++)] = p;
        if (pIn != qIn) {
          const double t = (plane - p[axis]) / (q[axis] - p[axis]);
          glm::dvec3 x = p + (q - p) * t;
          x[axis] = plane;  // exactly on the plane, whatever the rounding
          dst[size_t(n++)] = x;
        }
      }
      count = n;
      cur = 1 - cur;
    }
  }
  if (count == 0) return Box3f{};
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
  for (int i = 0; i < count; ++i) {
    lo = glm::min(lo, poly[size_t(cur)][size_t(i)]);
    hi = glm::max(hi, poly[size_t(cur)][size_t(i)]);
  }
  Box3f r;
  for (int axis = 0; axis < 3; ++axis) {
    r.lo[axis] = floatAtOrBelow(lo[axis]);
    r.hi[axis] = floatAtOrAbove(hi[axis]);
  }
  return r.intersection(box).intersection(triangleBox);
}

KdTree::KdTree() {
  nodes_.emplace_back();
  finishBuild();
}

void KdTree::finishBuild() {
  VS_CHECK_LT(nodes_.size(), size_t(1) << 30);
  VS_CHECK_LT(itemIndices_.size(), size_t(1) << 30);
  traversal_.resize(nodes_.size());
  for (size_t i = 0; i < nodes_.size(); ++i) {
    const KdNode& n = nodes_[i];
    TraversalNode& t = traversal_[i];
    if (n.isLeaf()) {
      t.bits = kLeafBits | (n.firstItem << 2);
      t.itemCount = n.itemCount;
    } else {
      VS_CHECK_EQ(size_t(n.children[0]), i + 1);  // the depth-first layout
      t.bits = uint32_t(n.axis) | (uint32_t(n.children[1]) << 2);
      t.split = n.split;
    }
  }
  computeRopes();
  computeStats();
}

KdTree KdTree::build(std::span<const Box3f> itemBounds, const KdBuildOptions& options,
                     const KdItemClipper& clipItem) {
  VS_CHECK_LE(itemBounds.size(), size_t(std::numeric_limits<uint32_t>::max()));
  VS_CHECK(options.emptyBonus >= 0.0f && options.emptyBonus < 1.0f);
  Stopwatch watch;

  std::vector<ItemRef> refs;
  refs.reserve(itemBounds.size());
  Box3f rootBox;
  for (size_t i = 0; i < itemBounds.size(); ++i) {
    if (!isUsableBox(itemBounds[i])) continue;
    refs.push_back(ItemRef{uint32_t(i), itemBounds[i]});
    rootBox.extend(itemBounds[i]);
  }
  const size_t skipped = itemBounds.size() - refs.size();

  int maxDepth = options.maxDepth;
  if (maxDepth <= 0)
    maxDepth = int(std::lround(8.0 + 1.3 * std::log2(double(std::max<size_t>(refs.size(), 1)))));
  maxDepth = std::min(maxDepth, kMaxDepth);

  KdTree tree;
  if (!refs.empty()) {
    Subtree built;
    if (!options.parallel) built.nodes.reserve(2 * refs.size() + 1);
    const KdBuilder builder(options, clipItem, maxDepth);
    Scratch scratch;
    const int32_t rootIndex = builder.build(built, std::move(refs), rootBox, 0, scratch);

    // Lay the nodes out depth first, each node's lower child right after it.
    tree.nodes_.clear();
    size_t nodeCount = 0, itemCount = 0;
    countChunk(built, nodeCount, itemCount);
    tree.nodes_.reserve(nodeCount);
    tree.itemIndices_.reserve(itemCount);
    struct Pending {
      const Subtree* chunk;
      int32_t builtIndex, parent;
    };
    std::vector<Pending> stack{{&built, rootIndex, -1}};
    while (!stack.empty()) {
      Pending p = stack.back();
      stack.pop_back();
      if (p.builtIndex <= kExternal) {
        const Subtree::External& e = p.chunk->externals[size_t(kExternal - p.builtIndex)];
        p = Pending{e.chunk.get(), e.root, p.parent};
      }
      const auto index = int32_t(tree.nodes_.size());
      KdNode n = p.chunk->nodes[size_t(p.builtIndex)];
      n.parent = p.parent;
      if (p.parent >= 0) {
        KdNode& parent = tree.nodes_[size_t(p.parent)];
        // The lower child is pushed last, so it is laid out first.
        parent.children[parent.children[0] == kUnset ? 0 : 1] = index;
      }
      if (n.isLeaf()) {
        const auto first = uint32_t(tree.itemIndices_.size());
        const auto from = p.chunk->items.begin() + n.firstItem;
        tree.itemIndices_.insert(tree.itemIndices_.end(), from, from + n.itemCount);
        n.firstItem = first;
      } else {
        stack.push_back({p.chunk, n.children[1], index});
        stack.push_back({p.chunk, n.children[0], index});
        n.children = {kUnset, kUnset};  // filled in as the children are laid out
      }
      tree.nodes_.push_back(n);
    }
  }
  tree.finishBuild();
  tree.stats_.items = itemBounds.size();
  tree.stats_.skippedItems = skipped;
  tree.stats_.buildMs = watch.ms();
  return tree;
}

KdTree KdTree::buildOverObjects(const Scene& scene, const KdBuildOptions& options) {
  std::vector<Box3f> bounds;
  bounds.reserve(scene.objects.size());
  for (const Object& o : scene.objects) bounds.push_back(o.bounds);
  return build(bounds, options);
}

KdTree KdTree::buildOverTriangles(const FlatTriangles& triangles, const KdBuildOptions& options) {
  std::vector<Box3f> bounds(triangles.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    Box3f& b = bounds[t];
    for (int k = 0; k < 3; ++k) b.extend(triangles.vertex(t, k));
  }
  return build(bounds, options, [&triangles](uint32_t t, const Box3f& box) {
    return clippedTriangleBounds(triangles.vertex(t, 0), triangles.vertex(t, 1),
                                 triangles.vertex(t, 2), box);
  });
}

int32_t KdTree::leafContaining(const glm::vec3& p) const {
  if (!nodes_.front().box.contains(p)) return -1;
  int32_t index = root();
  while (!nodes_[size_t(index)].isLeaf()) {
    const KdNode& n = nodes_[size_t(index)];
    index = n.children[p[n.axis] <= n.split ? 0 : 1];
  }
  return index;
}

void KdTree::computeRopes() {
  // Parents precede their children in nodes_, so each node's ropes are final
  // before its children inherit them.
  for (size_t i = 0; i < nodes_.size(); ++i) {
    const KdNode& n = nodes_[i];
    if (n.isLeaf()) continue;
    const int a = n.axis;
    for (int side = 0; side < 2; ++side) {
      KdNode& child = nodes_[size_t(n.children[size_t(side)])];
      child.ropes = n.ropes;
      // The face on the split plane looks at the sibling.
      child.ropes[size_t(kdFace(a, side == 0))] = n.children[size_t(1 - side)];
      for (int face = 0; face < 6; ++face) {
        int32_t& rope = child.ropes[size_t(face)];
        if (rope < 0) continue;
        const int faceAxis = face / 2;
        const bool highFace = face % 2 == 1;
        // Move down the neighbour's subtree while a child contains the face.
        for (;;) {
          const KdNode& u = nodes_[size_t(rope)];
          if (u.isLeaf()) break;
          if (u.axis == faceAxis) {
            // The neighbour lies beyond the face, so the face is on its near
            // boundary: the low child for a high face and vice versa.
            rope = u.children[highFace ? 0 : 1];
          } else if (child.box.hi[u.axis] <= u.split) {
            rope = u.children[0];
          } else if (child.box.lo[u.axis] >= u.split) {
            rope = u.children[1];
          } else {
            break;  // the face straddles u's plane: u is the smallest
          }
        }
      }
    }
  }
}

void KdTree::computeStats() {
  stats_ = KdStats{};
  stats_.nodes = nodes_.size();
  for (const KdNode& n : nodes_) {
    stats_.maxDepth = std::max(stats_.maxDepth, int(n.depth));
    if (!n.isLeaf()) continue;
    ++stats_.leaves;
    if (n.itemCount == 0) ++stats_.emptyLeaves;
    stats_.itemReferences += n.itemCount;
  }
  stats_.meanItemsPerLeaf =
      stats_.leaves ? double(stats_.itemReferences) / double(stats_.leaves) : 0.0;
}

}  // namespace vistream
