// Tests of the kD-tree (common/spatial/kdtree.h) and of the ray query back end
// built on it (common/raycast/kdtree_ray_query.cpp). Oracles: brute force over
// all items, all nodes or all triangles.
#include "common/spatial/kdtree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "common/raycast/ray_query.h"
#include "common/raycast/triangle_intersect.h"
#include "tests/common/support/triangle_soups.h"

namespace vistream {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// ---- fixtures ------------------------------------------------------------------

// Random boxes in [0, 100]^3 with every awkward kind mixed in: flat boxes,
// points, exact duplicates and boxes sharing coordinates (rounded to
// integers), so that split planes often coincide with item boundaries.
std::vector<Box3f> randomBoxes(size_t count, uint32_t seed, float maxSize = 12.0f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(0.0f, 100.0f), size(0.0f, maxSize);
  std::uniform_int_distribution<int> kind(0, 9);
  std::vector<Box3f> boxes;
  while (boxes.size() < count) {
    const glm::vec3 lo(pos(rng), pos(rng), pos(rng));
    glm::vec3 hi = lo + glm::vec3(size(rng), size(rng), size(rng));
    Box3f b(lo, hi);
    switch (kind(rng)) {
      case 0:
        b.hi.y = b.lo.y;
        break;  // flat
      case 1:
        b.hi = b.lo;
        break;  // point
      case 2:
        if (!boxes.empty()) b = boxes.back();
        break;  // duplicate
      case 3:
        b = Box3f(glm::round(b.lo), glm::round(b.hi));
        break;  // on the integer grid
      default:
        break;
    }
    boxes.push_back(b);
  }
  return boxes;
}

using testing::makeTriangles;

FlatTriangles randomTriangleSoup(size_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(0.0f, 50.0f), offset(-4.0f, 4.0f);
  std::vector<std::array<glm::vec3, 3>> tris;
  for (size_t i = 0; i < count; ++i) {
    const glm::vec3 a(pos(rng), pos(rng), pos(rng));
    tris.push_back({a, a + glm::vec3(offset(rng), offset(rng), offset(rng)),
                    a + glm::vec3(offset(rng), offset(rng), offset(rng))});
  }
  return makeTriangles(tris);
}

// A height field on the integer grid: cells [i, i+1] x [j, j+1], two triangles
// each sharing the diagonal, heights small integers (all zero when flat). All
// vertices and edge midpoints are exact in float.
FlatTriangles gridMesh(int cells, bool flat) {
  auto height = [&](int i, int j) { return flat ? 0.0f : float((i * 7 + j * 3) % 5); };
  auto v = [&](int i, int j) { return glm::vec3(float(i), float(j), height(i, j)); };
  std::vector<std::array<glm::vec3, 3>> tris;
  for (int i = 0; i < cells; ++i) {
    for (int j = 0; j < cells; ++j) {
      tris.push_back({v(i, j), v(i + 1, j), v(i + 1, j + 1)});
      tris.push_back({v(i, j), v(i + 1, j + 1), v(i, j + 1)});
    }
  }
  return makeTriangles(tris);
}

std::optional<TriangleHit> intersectTriangle(const FlatTriangles& tris, const Ray& ray, size_t t) {
  return intersectWatertight(glm::dvec3(ray.org), glm::dvec3(ray.dir), ray.tnear, ray.tfar,
                             glm::dvec3(tris.vertex(t, 0)), glm::dvec3(tris.vertex(t, 1)),
                             glm::dvec3(tris.vertex(t, 2)));
}

// The oracle: every triangle, in index order, so ties go to the smaller index.
Hit bruteForceFirstHit(const FlatTriangles& tris, const Ray& ray) {
  Hit best;
  double bestT = std::numeric_limits<double>::infinity();
  for (size_t t = 0; t < tris.size(); ++t) {
    if (tris.degenerate[t]) continue;
    if (const auto h = intersectTriangle(tris, ray, t); h && h->t < bestT) {
      bestT = h->t;
      best.triangle = uint32_t(t);
      best.t = float(h->t);
    }
  }
  return best;
}

std::vector<uint32_t> bruteForceAllHits(const FlatTriangles& tris, const Ray& ray) {
  std::vector<std::pair<float, uint32_t>> hits;
  for (size_t t = 0; t < tris.size(); ++t) {
    if (tris.degenerate[t]) continue;
    if (const auto h = intersectTriangle(tris, ray, t)) hits.emplace_back(float(h->t), uint32_t(t));
  }
  std::sort(hits.begin(), hits.end());
  std::vector<uint32_t> order;
  for (const auto& h : hits) order.push_back(h.second);
  return order;
}

std::vector<uint32_t> trianglesOf(const std::vector<Hit>& hits) {
  std::vector<uint32_t> order;
  for (const Hit& h : hits) order.push_back(h.triangle);
  return order;
}

// Entry and exit of the line org + t*dir through a closed box (slab test in
// double); nullopt when it misses.
std::optional<std::pair<double, double>> slab(const Box3f& box, const glm::vec3& org,
                                              const glm::vec3& dir) {
  double t0 = -std::numeric_limits<double>::infinity(), t1 = -t0;
  for (int a = 0; a < 3; ++a) {
    if (dir[a] == 0.0f) {
      if (org[a] < box.lo[a] || org[a] > box.hi[a]) return std::nullopt;
      continue;
    }
    double ta = (double(box.lo[a]) - org[a]) / dir[a], tb = (double(box.hi[a]) - org[a]) / dir[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (t0 > t1) return std::nullopt;
  return std::make_pair(t0, t1);
}

std::vector<int32_t> leavesOf(const KdTree& tree) {
  std::vector<int32_t> leaves;
  for (size_t i = 0; i < tree.nodes().size(); ++i)
    if (tree.nodes()[i].isLeaf()) leaves.push_back(int32_t(i));
  return leaves;
}

bool holds(const KdTree& tree, int32_t leaf, uint32_t item) {
  const auto items = tree.items(leaf);
  return std::binary_search(items.begin(), items.end(), item);
}

bool overlapsInterior(const Box3f& item, const Box3f& leaf) {
  for (int a = 0; a < 3; ++a)
    if (!(item.lo[a] < leaf.hi[a] && item.hi[a] > leaf.lo[a])) return false;
  return true;
}

bool contains(const Box3f& outer, const Box3f& inner) {
  return outer.contains(inner.lo) && outer.contains(inner.hi);
}

// ---- structure -------------------------------------------------------------------

TEST(KdTree, ChildBoxesPartitionTheirParentAtTheSplitPlane) {
  const std::vector<Box3f> boxes = randomBoxes(600, 1);
  const KdTree tree = KdTree::build(boxes);
  ASSERT_GT(tree.nodes().size(), 1u);
  Box3f all;
  for (const Box3f& b : boxes) all.extend(b);
  EXPECT_EQ(tree.bounds().lo, all.lo);
  EXPECT_EQ(tree.bounds().hi, all.hi);
  EXPECT_EQ(tree.node(KdTree::root()).parent, -1);
  for (size_t i = 0; i < tree.nodes().size(); ++i) {
    const KdNode& n = tree.nodes()[i];
    if (n.isLeaf()) {
      EXPECT_EQ(n.children[0], -1);
      EXPECT_TRUE(std::is_sorted(tree.items(int32_t(i)).begin(), tree.items(int32_t(i)).end()));
      continue;
    }
    EXPECT_TRUE(tree.items(int32_t(i)).empty());
    const int a = n.axis;
    EXPECT_LT(n.box.lo[a], n.split);
    EXPECT_GT(n.box.hi[a], n.split);
    const KdNode& below = tree.node(n.children[0]);
    const KdNode& above = tree.node(n.children[1]);
    for (const KdNode* child : {&below, &above}) {
      EXPECT_EQ(child->parent, int32_t(i));
      EXPECT_EQ(child->depth, n.depth + 1);
    }
    Box3f expectBelow = n.box, expectAbove = n.box;
    expectBelow.hi[a] = n.split;
    expectAbove.lo[a] = n.split;
    EXPECT_EQ(below.box.lo, expectBelow.lo);
    EXPECT_EQ(below.box.hi, expectBelow.hi);
    EXPECT_EQ(above.box.lo, expectAbove.lo);
    EXPECT_EQ(above.box.hi, expectAbove.hi);
  }
}

TEST(KdTree, EveryItemOverlappingALeafInteriorIsInThatLeaf) {
  const std::vector<Box3f> boxes = randomBoxes(500, 2);
  const KdTree tree = KdTree::build(boxes);
  for (const int32_t leaf : leavesOf(tree))
    for (uint32_t item = 0; item < boxes.size(); ++item)
      if (overlapsInterior(boxes[item], tree.node(leaf).box)) {
        EXPECT_TRUE(holds(tree, leaf, item)) << "leaf " << leaf << " item " << item;
      }
}

TEST(KdTree, LeavesHoldOnlyItemsThatTouchTheirBox) {
  const std::vector<Box3f> boxes = randomBoxes(500, 3);
  const KdTree tree = KdTree::build(boxes);
  for (const int32_t leaf : leavesOf(tree))
    for (const uint32_t item : tree.items(leaf))
      EXPECT_TRUE(boxes[item].overlaps(tree.node(leaf).box)) << "leaf " << leaf << " item " << item;
}

// Corners and centres of item boxes lie on split planes all the time (planes
// are taken from item boundaries), so this checks the closed-box bookkeeping
// that lets a ray through a plane find items touching it.
TEST(KdTree, EveryPointOfAnItemIsInALeafThatHoldsIt) {
  const std::vector<Box3f> boxes = randomBoxes(400, 4);
  const KdTree tree = KdTree::build(boxes);
  const std::vector<int32_t> leaves = leavesOf(tree);
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (uint32_t item = 0; item < boxes.size(); ++item) {
    const Box3f& b = boxes[item];
    std::vector<glm::vec3> points;
    for (int corner = 0; corner < 8; ++corner)
      points.emplace_back(corner & 1 ? b.hi.x : b.lo.x, corner & 2 ? b.hi.y : b.lo.y,
                          corner & 4 ? b.hi.z : b.lo.z);
    for (int k = 0; k < 4; ++k)
      points.push_back(
          glm::min(b.lo + (b.hi - b.lo) * glm::vec3(unit(rng), unit(rng), unit(rng)), b.hi));
    for (const glm::vec3& p : points) {
      bool found = false;
      for (const int32_t leaf : leaves)
        found = found || (tree.node(leaf).box.contains(p) && holds(tree, leaf, item));
      EXPECT_TRUE(found) << "item " << item << " point " << p.x << " " << p.y << " " << p.z;
    }
  }
}

TEST(KdTree, EveryItemIsReachableFromTheRoot) {
  const std::vector<Box3f> boxes = randomBoxes(800, 5);
  const KdTree tree = KdTree::build(boxes);
  std::vector<int> seen(boxes.size(), 0);
  tree.traverseFrontToBack(glm::vec3(50.0f), [&](int32_t node) {
    for (const uint32_t item : tree.items(node)) seen[item] = 1;
    return true;
  });
  for (size_t item = 0; item < boxes.size(); ++item) EXPECT_TRUE(seen[item]) << item;
}

TEST(KdTree, EachRopeLinksToTheSmallestNodeContainingTheWholeFace) {
  const std::vector<Box3f> boxes = randomBoxes(300, 6);
  const KdTree tree = KdTree::build(boxes);
  const auto& nodes = tree.nodes();
  ASSERT_GT(nodes.size(), 50u);
  for (size_t i = 0; i < nodes.size(); ++i) {
    const Box3f& box = nodes[i].box;
    for (int face = 0; face < 6; ++face) {
      const int a = face / 2;
      const bool high = face % 2 == 1;
      const float plane = high ? box.hi[a] : box.lo[a];
      // Brute force: nodes beyond the face whose box contains all of it.
      std::vector<int32_t> containing;
      for (size_t u = 0; u < nodes.size(); ++u) {
        const Box3f& ub = nodes[u].box;
        const bool beyond = high ? (ub.lo[a] == plane && ub.hi[a] > plane)
                                 : (ub.hi[a] == plane && ub.lo[a] < plane);
        bool coversFace = beyond;
        for (int b = 0; b < 3 && coversFace; ++b)
          if (b != a) coversFace = ub.lo[b] <= box.lo[b] && ub.hi[b] >= box.hi[b];
        if (coversFace) containing.push_back(int32_t(u));
      }
      const int32_t rope = tree.rope(int32_t(i), KdFace(face));
      if (containing.empty()) {
        EXPECT_EQ(rope, -1) << "node " << i << " face " << face;
        EXPECT_EQ(plane, high ? tree.bounds().hi[a] : tree.bounds().lo[a]);
        continue;
      }
      ASSERT_GE(rope, 0) << "node " << i << " face " << face;
      EXPECT_NE(std::find(containing.begin(), containing.end(), rope), containing.end())
          << "node " << i << " face " << face << " rope " << rope;
      for (const int32_t u : containing)  // no containing node is smaller
        EXPECT_TRUE(contains(nodes[size_t(u)].box, nodes[size_t(rope)].box))
            << "node " << i << " face " << face << " rope " << rope << " vs " << u;
    }
  }
}

TEST(KdTree, EmptyInputGivesOneEmptyLeafWithoutRopes) {
  const KdTree tree = KdTree::build(std::span<const Box3f>{});
  ASSERT_EQ(tree.nodes().size(), 1u);
  EXPECT_TRUE(tree.node(0).isLeaf());
  EXPECT_TRUE(tree.bounds().empty());
  EXPECT_TRUE(tree.items(0).empty());
  for (int face = 0; face < 6; ++face) EXPECT_EQ(tree.rope(0, KdFace(face)), -1);
  EXPECT_EQ(tree.stats().emptyLeaves, 1u);
  int leaves = 0;
  tree.traverseRay(glm::vec3(0.0f), glm::vec3(1.0f, 0.0f, 0.0f), 0.0f, kInf,
                   [&](int32_t, float, float) {
                     ++leaves;
                     return true;
                   });
  EXPECT_EQ(leaves, 0);
  EXPECT_EQ(tree.leafContaining(glm::vec3(0.0f)), -1);
  EXPECT_EQ(KdTree().nodes().size(), 1u);
}

TEST(KdTree, IdenticalItemsEndInOneLeaf) {
  const std::vector<Box3f> boxes(1000,
                                 Box3f(glm::vec3(1.0f, 2.0f, 3.0f), glm::vec3(4.0f, 5.0f, 6.0f)));
  const KdTree tree = KdTree::build(boxes);
  ASSERT_EQ(tree.nodes().size(), 1u);
  EXPECT_EQ(tree.items(0).size(), boxes.size());
}

TEST(KdTree, IdenticalItemsInsideLargerSceneShareOneLeaf) {
  std::vector<Box3f> boxes(500, Box3f(glm::vec3(1.0f), glm::vec3(2.0f)));
  boxes.emplace_back(glm::vec3(90.0f), glm::vec3(100.0f));
  const KdTree tree = KdTree::build(boxes);
  const int32_t leaf = tree.leafContaining(glm::vec3(1.5f));
  ASSERT_GE(leaf, 0);
  EXPECT_EQ(tree.items(leaf).size(), 500u);
  EXPECT_EQ(tree.stats().itemReferences, 501u);
}

TEST(KdTree, FlatItemsInOnePlaneAreSplitWithinThePlane) {
  std::vector<Box3f> boxes;
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j)
      boxes.emplace_back(glm::vec3(float(i), 7.0f, float(j)),
                         glm::vec3(float(i) + 0.5f, 7.0f, float(j) + 0.5f));
  const KdTree tree = KdTree::build(boxes);
  EXPECT_EQ(tree.bounds().lo.y, 7.0f);
  EXPECT_EQ(tree.bounds().hi.y, 7.0f);
  EXPECT_GT(tree.stats().leaves, 50u);
  EXPECT_EQ(tree.stats().itemReferences, boxes.size());  // the gaps make every split clean
  for (const KdNode& n : tree.nodes()) EXPECT_NE(n.axis, 1);
}

TEST(KdTree, ItemsWithEmptyOrNonFiniteBoxesAreSkipped) {
  std::vector<Box3f> boxes = randomBoxes(50, 7);
  boxes[3] = Box3f{};
  boxes[9].hi.x = std::numeric_limits<float>::quiet_NaN();
  boxes[11].lo.z = -kInf;
  const KdTree tree = KdTree::build(boxes);
  EXPECT_EQ(tree.stats().items, 50u);
  EXPECT_EQ(tree.stats().skippedItems, 3u);
  for (const int32_t leaf : leavesOf(tree))
    for (const uint32_t item : tree.items(leaf)) EXPECT_TRUE(item != 3 && item != 9 && item != 11);
}

TEST(KdTree, RespectsMaxDepthAndLeafItems) {
  const std::vector<Box3f> boxes = randomBoxes(2000, 8);
  KdBuildOptions options;
  options.maxDepth = 4;
  EXPECT_LE(KdTree::build(boxes, options).stats().maxDepth, 4);
  options.maxDepth = 0;
  options.leafItems = 50;
  const KdTree tree = KdTree::build(boxes, options);
  // Without clipping, the items below a node are the items it held, and a node
  // holding at most leafItems of them is never split.
  for (size_t i = 0; i < tree.nodes().size(); ++i) {
    if (tree.nodes()[i].isLeaf()) continue;
    std::set<uint32_t> items;
    std::vector<int32_t> stack{int32_t(i)};
    while (!stack.empty()) {
      const int32_t k = stack.back();
      stack.pop_back();
      if (tree.node(k).isLeaf()) {
        items.insert(tree.items(k).begin(), tree.items(k).end());
      } else {
        stack.push_back(tree.node(k).children[0]);
        stack.push_back(tree.node(k).children[1]);
      }
    }
    EXPECT_GT(items.size(), options.leafItems) << "node " << i;
  }
}

TEST(KdTree, StatisticsCountTheTree) {
  const std::vector<Box3f> boxes = randomBoxes(1000, 9);
  const KdTree tree = KdTree::build(boxes);
  const KdStats s = tree.stats();
  size_t leaves = 0, empty = 0, refs = 0;
  int depth = 0;
  for (size_t i = 0; i < tree.nodes().size(); ++i) {
    const KdNode& n = tree.nodes()[i];
    depth = std::max(depth, int(n.depth));
    if (!n.isLeaf()) continue;
    ++leaves;
    empty += tree.items(int32_t(i)).empty();
    refs += tree.items(int32_t(i)).size();
  }
  EXPECT_EQ(s.nodes, tree.nodes().size());
  EXPECT_EQ(s.leaves, leaves);
  EXPECT_EQ(s.nodes, 2 * leaves - 1);
  EXPECT_EQ(s.emptyLeaves, empty);
  EXPECT_EQ(s.itemReferences, refs);
  EXPECT_EQ(s.maxDepth, depth);
  EXPECT_DOUBLE_EQ(s.meanItemsPerLeaf, double(refs) / double(leaves));
  EXPECT_GE(s.buildMs, 0.0);
  EXPECT_EQ(s.items, 1000u);
}

TEST(KdTree, ParallelAndSerialBuildsAreIdentical) {
  const std::vector<Box3f> boxes = randomBoxes(20000, 10, 1.0f);  // above the parallel threshold
  KdBuildOptions serial;
  serial.parallel = false;
  const KdTree a = KdTree::build(boxes, serial);
  const KdTree b = KdTree::build(boxes);
  ASSERT_EQ(a.nodes().size(), b.nodes().size());
  for (size_t i = 0; i < a.nodes().size(); ++i) {
    const KdNode &x = a.nodes()[i], &y = b.nodes()[i];
    ASSERT_EQ(x.axis, y.axis) << i;
    ASSERT_EQ(x.split, y.split) << i;
    ASSERT_EQ(x.children, y.children) << i;
    ASSERT_EQ(x.ropes, y.ropes) << i;
    ASSERT_TRUE(std::equal(a.items(int32_t(i)).begin(), a.items(int32_t(i)).end(),
                           b.items(int32_t(i)).begin(), b.items(int32_t(i)).end()))
        << i;
  }
}

TEST(KdTree, BuildsOverSceneObjects) {
  Scene scene;
  for (int i = 0; i < 30; ++i) {
    Object o;
    o.name = "block" + std::to_string(i);
    o.bounds = Box3f(glm::vec3(float(i % 6) * 10.0f, 0.0f, float(i / 6) * 10.0f),
                     glm::vec3(float(i % 6) * 10.0f + 8.0f, float(i % 4 + 1) * 5.0f,
                               float(i / 6) * 10.0f + 8.0f));
    scene.objects.push_back(o);
  }
  const KdTree tree = KdTree::buildOverObjects(scene);
  EXPECT_GT(tree.stats().leaves, 1u);
  const int32_t leaf = tree.leafContaining(glm::vec3(14.0f, 1.0f, 24.0f));  // inside object 2*6+1
  ASSERT_GE(leaf, 0);
  EXPECT_TRUE(holds(tree, leaf, 13));
}

TEST(KdTree, LeafContainingFindsTheLeafAroundAPoint) {
  const std::vector<Box3f> boxes = randomBoxes(500, 11);
  const KdTree tree = KdTree::build(boxes);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> pos(-5.0f, 115.0f);
  for (int k = 0; k < 500; ++k) {
    const glm::vec3 p(pos(rng), pos(rng), pos(rng));
    const int32_t leaf = tree.leafContaining(p);
    if (!tree.bounds().contains(p)) {
      EXPECT_EQ(leaf, -1);
      continue;
    }
    ASSERT_GE(leaf, 0);
    EXPECT_TRUE(tree.node(leaf).isLeaf());
    EXPECT_TRUE(tree.node(leaf).box.contains(p));
  }
}

// ---- split clipping ----------------------------------------------------------------

TEST(ClippedTriangleBounds, IsTheBoxOfThePartInsideTheClipBox) {
  const glm::vec3 a(0.0f), b(10.0f, 0.0f, 0.0f), c(0.0f, 10.0f, 0.0f);
  const Box3f inside = clippedTriangleBounds(a, b, c, Box3f(glm::vec3(-1.0f), glm::vec3(20.0f)));
  EXPECT_EQ(inside.lo, glm::vec3(0.0f));
  EXPECT_EQ(inside.hi, glm::vec3(10.0f, 10.0f, 0.0f));
  // Beyond the hypotenuse x + y = 10: nothing.
  EXPECT_TRUE(clippedTriangleBounds(
                  a, b, c, Box3f(glm::vec3(6.0f, 6.0f, -1.0f), glm::vec3(9.0f, 9.0f, 1.0f)))
                  .empty());
  // A slab x in [4, 6] cuts the triangle to y in [0, 6].
  const Box3f slabPart = clippedTriangleBounds(
      a, b, c, Box3f(glm::vec3(4.0f, -1.0f, -1.0f), glm::vec3(6.0f, 20.0f, 1.0f)));
  EXPECT_EQ(slabPart.lo, glm::vec3(4.0f, 0.0f, 0.0f));
  EXPECT_EQ(slabPart.hi, glm::vec3(6.0f, 6.0f, 0.0f));
  // Touching the box only at the corner (5, 5) leaves a single point.
  const Box3f corner = clippedTriangleBounds(
      a, b, c, Box3f(glm::vec3(5.0f, 5.0f, 0.0f), glm::vec3(8.0f, 8.0f, 1.0f)));
  EXPECT_EQ(corner.lo, glm::vec3(5.0f, 5.0f, 0.0f));
  EXPECT_EQ(corner.hi, glm::vec3(5.0f, 5.0f, 0.0f));
}

TEST(ClippedTriangleBounds, ContainsEveryPointOfTheTriangleInsideTheBox) {
  std::mt19937 rng(12);
  std::uniform_real_distribution<float> pos(-10.0f, 10.0f), unit(0.0f, 1.0f);
  for (int k = 0; k < 2000; ++k) {
    const glm::vec3 a(pos(rng), pos(rng), pos(rng)), b(pos(rng), pos(rng), pos(rng)),
        c(pos(rng), pos(rng), pos(rng));
    const Box3f box(glm::vec3(pos(rng), pos(rng), pos(rng)),
                    glm::vec3(pos(rng), pos(rng), pos(rng)));
    const Box3f part = clippedTriangleBounds(a, b, c, box);
    for (int s = 0; s < 50; ++s) {
      float u = unit(rng), v = unit(rng);
      if (u + v > 1.0f) u = 1.0f - u, v = 1.0f - v;
      const glm::vec3 p = a + u * (b - a) + v * (c - a);
      if (box.contains(p)) {
        EXPECT_TRUE(part.contains(p)) << k;
      }
    }
  }
}

TEST(KdTree, TrianglePointsAreInALeafThatHoldsTheTriangle) {
  const FlatTriangles soup = randomTriangleSoup(1500, 13);
  const KdTree tree = KdTree::buildOverTriangles(soup);
  const std::vector<int32_t> leaves = leavesOf(tree);
  std::mt19937 rng(13);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (uint32_t t = 0; t < soup.size(); t += 3) {
    const glm::vec3 a = soup.vertex(t, 0), b = soup.vertex(t, 1), c = soup.vertex(t, 2);
    std::vector<glm::vec3> points{a, b, c, (a + b) * 0.5f};
    for (int s = 0; s < 6; ++s) {
      float u = unit(rng), v = unit(rng);
      if (u + v > 1.0f) u = 1.0f - u, v = 1.0f - v;
      points.push_back(a + u * (b - a) + v * (c - a));
    }
    for (const glm::vec3& p : points) {
      bool found = false;
      for (const int32_t leaf : leaves)
        found = found || (tree.node(leaf).box.contains(p) && holds(tree, leaf, t));
      EXPECT_TRUE(found) << "triangle " << t;
    }
  }
}

TEST(KdTree, SplitClippingKeepsTrianglesOutOfLeavesTheyOnlyBoxOverlap) {
  const FlatTriangles soup = randomTriangleSoup(3000, 14);
  std::vector<Box3f> bounds;
  for (size_t t = 0; t < soup.size(); ++t) bounds.push_back(soup.triangleBounds(t));
  const KdTree clipped = KdTree::buildOverTriangles(soup);
  const KdTree boxed = KdTree::build(bounds);
  EXPECT_LT(double(clipped.stats().itemReferences) /
                double(clipped.stats().leaves - clipped.stats().emptyLeaves),
            double(boxed.stats().itemReferences) /
                double(boxed.stats().leaves - boxed.stats().emptyLeaves));
}

// ---- traversal -----------------------------------------------------------------------

TEST(KdTree, RayVisitsTheLeavesItCrossesInNondecreasingEntryDistance) {
  const std::vector<Box3f> boxes = randomBoxes(800, 15);
  const KdTree tree = KdTree::build(boxes);
  const std::vector<int32_t> leaves = leavesOf(tree);
  std::mt19937 rng(15);
  std::uniform_real_distribution<float> pos(-20.0f, 120.0f), dirc(-1.0f, 1.0f), tlim(0.0f, 200.0f);
  for (int r = 0; r < 300; ++r) {
    const glm::vec3 org(pos(rng), pos(rng), pos(rng)), dir(dirc(rng), dirc(rng), dirc(rng));
    const float tnear = r % 3 == 0 ? tlim(rng) * 0.3f : 0.0f;
    const float tfar = r % 2 == 0 ? tlim(rng) : kInf;
    std::vector<int32_t> visited;
    float lastEnter = -kInf;
    tree.traverseRay(org, dir, tnear, tfar, [&](int32_t leaf, float tEnter, float tExit) {
      EXPECT_TRUE(tree.node(leaf).isLeaf());
      EXPECT_GE(tEnter, lastEnter);
      EXPECT_LE(tEnter, tExit);
      lastEnter = tEnter;
      visited.push_back(leaf);
      return true;
    });
    // Geometric entries of the visited leaves are nondecreasing too.
    double lastGeometric = -std::numeric_limits<double>::infinity();
    for (const int32_t leaf : visited) {
      const auto span = slab(tree.node(leaf).box, org, dir);
      ASSERT_TRUE(span.has_value());
      const double enter = std::max(span->first, double(tnear));
      EXPECT_GE(enter, lastGeometric - 1e-4);
      EXPECT_LE(enter, double(tfar) + 1e-3);
      lastGeometric = enter;
    }
    // Every leaf the segment really crosses is visited, once.
    std::set<int32_t> visitedSet(visited.begin(), visited.end());
    EXPECT_EQ(visitedSet.size(), visited.size());
    for (const int32_t leaf : leaves) {
      const auto span = slab(tree.node(leaf).box, org, dir);
      if (span &&
          std::min(span->second, double(tfar)) - std::max(span->first, double(tnear)) > 1e-3) {
        EXPECT_TRUE(visitedSet.count(leaf)) << "ray " << r << " leaf " << leaf;
      }
    }
  }
}

TEST(KdTree, RayInASplitPlaneVisitsTheLeavesOnBothSides) {
  // Two slabs of items meeting at x = 5, so the root splits there.
  std::vector<Box3f> boxes;
  for (int k = 0; k < 8; ++k) {
    boxes.emplace_back(glm::vec3(0.0f, float(k), 0.0f), glm::vec3(5.0f, float(k) + 0.5f, 1.0f));
    boxes.emplace_back(glm::vec3(5.0f, float(k), 0.0f), glm::vec3(10.0f, float(k) + 0.5f, 1.0f));
  }
  const KdTree tree = KdTree::build(boxes);
  ASSERT_TRUE(std::any_of(tree.nodes().begin(), tree.nodes().end(),
                          [](const KdNode& n) { return n.axis == 0 && n.split == 5.0f; }));
  std::set<uint32_t> met;
  tree.traverseRay(glm::vec3(5.0f, -1.0f, 0.5f), glm::vec3(0.0f, 1.0f, 0.0f), 0.0f, kInf,
                   [&](int32_t leaf, float, float) {
                     met.insert(tree.items(leaf).begin(), tree.items(leaf).end());
                     return true;
                   });
  EXPECT_EQ(met.size(), boxes.size());
}

TEST(KdTree, RayTraversalStopsWhenTheCallbackSaysSo) {
  const KdTree tree = KdTree::build(randomBoxes(800, 16));
  int visits = 0;
  tree.traverseRay(glm::vec3(-1.0f, 50.0f, 50.0f), glm::vec3(1.0f, 0.01f, 0.02f), 0.0f, kInf,
                   [&](int32_t, float, float) { return ++visits < 2; });
  EXPECT_EQ(visits, 2);
  visits = 0;
  tree.traverseRay(glm::vec3(-1.0f, 50.0f, 50.0f), glm::vec3(1.0f, 0.01f, 0.02f), 0.0f, kInf,
                   [&](int32_t, float tEnter, float) {
                     ++visits;
                     return visits == 1 ? tEnter : kInf;  // shortening to here skips the rest
                   });
  EXPECT_EQ(visits, 1);
}

TEST(KdTree, FrontToBackOrderPutsEveryLeafBeforeTheLeavesBehindIt) {
  const std::vector<Box3f> boxes = randomBoxes(600, 17);
  const KdTree tree = KdTree::build(boxes);
  const std::vector<int32_t> leaves = leavesOf(tree);
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> pos(-20.0f, 120.0f), dirc(-1.0f, 1.0f);
  for (int v = 0; v < 10; ++v) {
    const glm::vec3 viewpoint(pos(rng), pos(rng), pos(rng));
    std::vector<int> rank(tree.nodes().size(), -1);
    int next = 0;
    tree.traverseFrontToBack(viewpoint, [&](int32_t node) {
      EXPECT_EQ(rank[size_t(node)], -1);
      rank[size_t(node)] = next++;
      return true;
    });
    EXPECT_EQ(size_t(next), tree.nodes().size());
    for (size_t i = 0; i < tree.nodes().size(); ++i)
      if (tree.nodes()[i].parent >= 0) {
        EXPECT_LT(rank[size_t(tree.nodes()[i].parent)], rank[i]);
      }
    // Along any ray from the viewpoint, leaves come in the order it meets them.
    for (int r = 0; r < 100; ++r) {
      const glm::vec3 dir(dirc(rng), dirc(rng), dirc(rng));
      std::vector<std::pair<double, int32_t>> crossed;
      for (const int32_t leaf : leaves) {
        const auto span = slab(tree.node(leaf).box, viewpoint, dir);
        if (span && span->second > 0.0 && span->second - std::max(span->first, 0.0) > 1e-4)
          crossed.emplace_back(std::max(span->first, 0.0), leaf);
      }
      std::sort(crossed.begin(), crossed.end());
      for (size_t k = 1; k < crossed.size(); ++k)
        EXPECT_LT(rank[size_t(crossed[k - 1].second)], rank[size_t(crossed[k].second)]);
    }
  }
}

TEST(KdTree, FrontToBackSkipsSubtreesTheVisitorDeclines) {
  const KdTree tree = KdTree::build(randomBoxes(500, 18));
  std::vector<int32_t> visited;
  tree.traverseFrontToBack(glm::vec3(0.0f), [&](int32_t node) {
    visited.push_back(node);
    return tree.node(node).depth < 2;
  });
  EXPECT_EQ(visited.size(), 7u);
  for (const int32_t node : visited) EXPECT_LE(tree.node(node).depth, 2);
}

// ---- ray query ---------------------------------------------------------------------

void expectAgreesWithBruteForce(const RayQuery& query, const FlatTriangles& tris, const Ray& ray,
                                const char* what, int index) {
  const Hit expected = bruteForceFirstHit(tris, ray);
  const Hit got = query.firstHit(ray);
  EXPECT_EQ(got.triangle, expected.triangle) << what << " ray " << index;
  if (expected.valid() && got.valid()) {
    EXPECT_EQ(got.t, expected.t) << what << " ray " << index;
    const glm::vec3 a = tris.vertex(got.triangle, 0), b = tris.vertex(got.triangle, 1),
                    c = tris.vertex(got.triangle, 2);
    EXPECT_EQ(got.normal, glm::cross(b - a, c - a));
  }
  EXPECT_EQ(query.occluded(ray), expected.valid()) << what << " ray " << index;
  std::vector<Hit> hits;
  query.allHits(ray, hits);
  EXPECT_EQ(trianglesOf(hits), bruteForceAllHits(tris, ray)) << what << " ray " << index;
}

TEST(KdTreeRayQuery, AgreesWithBruteForceOnRandomTriangleSoups) {
  for (uint32_t seed = 20; seed < 23; ++seed) {
    const FlatTriangles soup = randomTriangleSoup(1500, seed);
    const auto query = makeKdTreeRayQuery(soup);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> pos(-10.0f, 60.0f), dirc(-1.0f, 1.0f), t(0.0f, 40.0f);
    for (int r = 0; r < 600; ++r) {
      Ray ray;
      ray.org = glm::vec3(pos(rng), pos(rng), pos(rng));
      ray.dir = glm::vec3(dirc(rng), dirc(rng), dirc(rng)) * (r % 4 == 0 ? 7.5f : 1.0f);
      if (r % 3 == 1) ray.tnear = t(rng) * 0.25f;
      if (r % 5 == 2) ray.tfar = t(rng);
      expectAgreesWithBruteForce(*query, soup, ray, "soup", r);
    }
  }
}

// Rays through vertices and edge midpoints of an integer grid. The directions
// have power-of-two ratios to their z component, so the watertight test's
// shear is exact too and every ray must hit, even one that only grazes a
// height field at a silhouette vertex (no seam lets a ray through).
void checkGridSeams(const FlatTriangles& grid, int cells) {
  const auto query = makeKdTreeRayQuery(grid);
  const std::vector<glm::vec3> directions{{0, 0, 1}, {1, 2, 4}, {-1, 1, 2}, {2, -1, 4},
                                          {1, 1, 2}, {0, 1, 4}, {-1, 0, 1}, {1, -1, 1}};
  int index = 0;
  for (int i = 1; i < cells; ++i) {
    for (int j = 1; j < cells; ++j) {
      // Vertex (i, j), and midpoints of the x edge, y edge and diagonal from it.
      const glm::vec3 v = grid.vertex(size_t(2 * ((i - 1) * cells + (j - 1))), 2);  // (i, j) corner
      ASSERT_EQ(v.x, float(i));
      ASSERT_EQ(v.y, float(j));
      const glm::vec3 vx = grid.vertex(size_t(2 * (i * cells + (j - 1))), 2);  // (i+1, j)
      const glm::vec3 vy = grid.vertex(size_t(2 * ((i - 1) * cells + j)), 2);  // (i, j+1)
      const glm::vec3 vd = grid.vertex(size_t(2 * (i * cells + j)), 2);        // (i+1, j+1)
      for (const glm::vec3& target : {v, (v + vx) * 0.5f, (v + vy) * 0.5f, (v + vd) * 0.5f}) {
        for (const glm::vec3& d : directions) {
          Ray ray;
          ray.org = target + 8.0f * d;
          ray.dir = -d;
          const Hit hit = query->firstHit(ray);
          EXPECT_TRUE(hit.valid()) << "ray " << index;
          EXPECT_TRUE(query->occluded(ray)) << "ray " << index;
          expectAgreesWithBruteForce(*query, grid, ray, "grid", index);
          // Straight down onto the flat grid, the first hit is at the target.
          if (d == glm::vec3(0, 0, 1) && target.z == 0.0f) {
            EXPECT_EQ(hit.t, 8.0f);
          }
          ++index;
        }
      }
    }
  }
}

TEST(KdTreeRayQuery, RaysThroughSharedEdgesAndVerticesOfAFlatGridHit) {
  checkGridSeams(gridMesh(12, true), 12);
}

TEST(KdTreeRayQuery, RaysThroughSharedEdgesAndVerticesOfAHeightFieldHit) {
  checkGridSeams(gridMesh(12, false), 12);
}

TEST(KdTreeRayQuery, EmptySceneIsNeverHit) {
  const FlatTriangles empty;
  const auto query = makeKdTreeRayQuery(empty);
  Ray ray;
  EXPECT_FALSE(query->firstHit(ray).valid());
  EXPECT_FALSE(query->occluded(ray));
  std::vector<Hit> hits(3);
  query->allHits(ray, hits);
  EXPECT_TRUE(hits.empty());
}

TEST(KdTreeRayQuery, SingleTriangleIsHitInsideAndMissedOutside) {
  const FlatTriangles one =
      makeTriangles({{glm::vec3(0, 0, -5), glm::vec3(4, 0, -5), glm::vec3(0, 4, -5)}});
  const auto query = makeKdTreeRayQuery(one);
  Ray ray;
  ray.org = glm::vec3(1.0f, 1.0f, 0.0f);
  const Hit hit = query->firstHit(ray);
  ASSERT_TRUE(hit.valid());
  EXPECT_EQ(hit.triangle, 0u);
  EXPECT_FLOAT_EQ(hit.t, 5.0f);
  EXPECT_FLOAT_EQ(hit.u, 0.25f);
  EXPECT_FLOAT_EQ(hit.v, 0.25f);
  ray.tfar = 4.0f;
  EXPECT_FALSE(query->occluded(ray));
  ray.tfar = kInf;
  ray.org = glm::vec3(3.0f, 3.0f, 0.0f);
  EXPECT_FALSE(query->firstHit(ray).valid());
  ray.org = glm::vec3(2.0f, 2.0f, 0.0f);  // on the hypotenuse: closed triangle
  EXPECT_TRUE(query->occluded(ray));
}

TEST(KdTreeRayQuery, DegenerateTrianglesAreNeverHit) {
  FlatTriangles tris = makeTriangles({
      {glm::vec3(0, 0, -2), glm::vec3(4, 0, -2), glm::vec3(2, 0, -2)},     // collinear
      {glm::vec3(1, 1, -3), glm::vec3(1, 1, -3), glm::vec3(0, 4, -3)},     // repeated vertex
      {glm::vec3(-4, -4, -4), glm::vec3(4, -4, -4), glm::vec3(0, 4, -4)},  // flagged below
      {glm::vec3(-8, -8, -9), glm::vec3(8, -8, -9), glm::vec3(0, 8, -9)},
  });
  ASSERT_TRUE(tris.degenerate[0] && tris.degenerate[1]);
  tris.degenerate[2] = 1;  // the interface trusts the flag
  const auto query = makeKdTreeRayQuery(tris);
  for (const glm::vec3& org : {glm::vec3(1, 0, 0), glm::vec3(1, 1, 0), glm::vec3(0.5f, 2, 0)}) {
    Ray ray;
    ray.org = org;
    const Hit hit = query->firstHit(ray);
    ASSERT_TRUE(hit.valid());
    EXPECT_EQ(hit.triangle, 3u);
    std::vector<Hit> hits;
    query->allHits(ray, hits);
    ASSERT_EQ(hits.size(), 1u);
    EXPECT_EQ(hits[0].triangle, 3u);
  }
}

TEST(KdTreeRayQuery, FirstHitTiesResolveToTheSmallerTriangleIndex) {
  // Many copies of one quad's triangles among clutter, so the tree splits
  // around them; the copies tie at every hit.
  std::vector<std::array<glm::vec3, 3>> tris;
  const FlatTriangles clutter = randomTriangleSoup(400, 30);
  for (size_t t = 0; t < clutter.size(); ++t)
    tris.push_back({clutter.vertex(t, 0) + glm::vec3(0, 0, 60),
                    clutter.vertex(t, 1) + glm::vec3(0, 0, 60),
                    clutter.vertex(t, 2) + glm::vec3(0, 0, 60)});
  for (int copy = 0; copy < 5; ++copy) {
    tris.push_back({glm::vec3(0, 0, 0), glm::vec3(50, 0, 0), glm::vec3(50, 50, 0)});
    tris.push_back({glm::vec3(0, 0, 0), glm::vec3(50, 50, 0), glm::vec3(0, 50, 0)});
  }
  const FlatTriangles flat = makeTriangles(tris);
  const auto query = makeKdTreeRayQuery(flat);
  std::mt19937 rng(30);
  std::uniform_real_distribution<float> pos(1.0f, 49.0f);
  for (int r = 0; r < 200; ++r) {
    Ray ray;
    ray.org = glm::vec3(pos(rng), pos(rng), -10.0f);
    ray.dir = glm::vec3(0.0f, 0.0f, 1.0f);
    if (r % 2) ray.org.y = ray.org.x;  // on the shared diagonal
    const Hit hit = query->firstHit(ray);
    ASSERT_TRUE(hit.valid());
    EXPECT_EQ(hit.triangle, bruteForceFirstHit(flat, ray).triangle);
    EXPECT_LE(hit.triangle, 401u);
    std::vector<Hit> hits;
    query->allHits(ray, hits);
    EXPECT_EQ(trianglesOf(hits), bruteForceAllHits(flat, ray));
  }
}

TEST(KdTreeRayQuery, IsNamedKdtree) {
  const FlatTriangles empty;
  EXPECT_STREQ(makeKdTreeRayQuery(empty)->name(), "kdtree");
}

}  // namespace
}  // namespace vistream
