// Bittner and Havran 2001, "Exploiting coherence in hierarchical visibility
// algorithms": the classical hierarchical culling (section "Classical
// Approach"), hierarchy updating with pull-up (Figure 4) and conservative
// hierarchy updating (section "Conservative Hierarchy Updating").
#include "server/visibility/hierarchical_culling.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <map>
#include <numeric>
#include <optional>

#include "common/core/error.h"
#include "common/core/timer.h"
#include "common/core/view.h"

namespace vistream {

namespace {
// Indexed by CullingMethod.
constexpr std::array<const char*, 5> kCullingMethodNames{"A", "B", "C", "D", "adaptive"};
}  // namespace

CullingMethod parseCullingMethod(const std::string& name) {
  for (size_t i = 0; i < kCullingMethodNames.size(); ++i)
    if (name == kCullingMethodNames[i]) return CullingMethod(i);
  throwInputError("--method: expected A, B, C, D or adaptive, got '{}'", name);
}

const char* cullingMethodName(CullingMethod m) {
  return size_t(m) < kCullingMethodNames.size() ? kCullingMethodNames[size_t(m)] : "?";
}

namespace {

// Convex planar outline of a face, shrunk slightly towards its centre if float
// noise bends it (so that it can never be larger than the geometry); empty if
// the face is not planar and convex.
std::vector<glm::dvec3> convexFaceOutline(const std::vector<glm::dvec3>& verts,
                                          double triangleArea) {
  if (verts.size() < 3) return {};
  glm::dvec3 c(0.0);
  for (const auto& v : verts) c += v;
  c /= double(verts.size());
  glm::dvec3 n(0.0);
  for (size_t i = 0; i < verts.size(); ++i)
    n += glm::cross(verts[i] - c, verts[(i + 1) % verts.size()] - c);
  if (!(glm::length(n) > 0.0)) return {};
  n = glm::normalize(n);
  const glm::dvec3 u = glm::normalize(std::abs(n.x) < 0.9 ? glm::cross(n, glm::dvec3(1, 0, 0))
                                                          : glm::cross(n, glm::dvec3(0, 1, 0)));
  const glm::dvec3 w = glm::cross(n, u);
  double mag = 0.0, bend = 0.0;
  for (const auto& v : verts) {
    const double off = std::abs(glm::dot(v - c, n));
    if (off > 1e-4 * (1.0 + glm::length(v - c))) return {};  // not planar
    bend = std::max(bend, off);
    mag = std::max(mag, glm::length(v));
  }
  // Angular order around the centre, then check convexity and area.
  std::vector<size_t> order(verts.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    const glm::dvec3 da = verts[a] - c, db = verts[b] - c;
    return std::atan2(glm::dot(da, w), glm::dot(da, u)) <
           std::atan2(glm::dot(db, w), glm::dot(db, u));
  });
  double area = 0.0;
  for (size_t i = 0; i < order.size(); ++i) {
    const glm::dvec3 a = verts[order[i]] - c, b = verts[order[(i + 1) % order.size()]] - c;
    area += 0.5 * glm::dot(glm::cross(a, b), n);
    const glm::dvec3 nxt = verts[order[(i + 2) % order.size()]] - c;
    if (glm::dot(glm::cross(b - a, nxt - b), n) < -1e-9 * (1.0 + mag * mag))
      return {};  // reflex corner
  }
  if (std::abs(area - triangleArea) > 1e-6 * (1.0 + area)) return {};  // holes or overlaps
  // A face planar to within double rounding (axis-aligned walls, say) is
  // used as it is, so faces sharing an edge fuse across it; a face bent by
  // float noise is shrunk so that it never covers more than its triangles.
  if (bend <= 1e-13 * (1.0 + mag)) {
    std::vector<glm::dvec3> out;
    for (size_t i : order) out.push_back(verts[i]);
    return out;
  }
  const double margin = 1e-7 * (1.0 + mag) + 1e-5;
  std::vector<glm::dvec3> out;
  for (size_t i : order) {
    const glm::dvec3 d = c - verts[i];
    const double len = glm::length(d);
    out.push_back(len > 2.0 * margin ? verts[i] + d * (margin / len) : c);
  }
  return out;
}

struct Frustum {
  glm::dvec3 eye;
  glm::dvec3 normals[4];
  // 0: outside, 1: partly inside, 2: entirely inside (conservative: when in
  // doubt, not outside).
  int classify(const Box3f& b) const {
    bool allInside = true;
    for (const glm::dvec3& n : normals) {
      int outside = 0;
      for (int k = 0; k < 8; ++k) {
        const glm::dvec3 c(b.corner(k));
        const double s = glm::dot(c - eye, n);
        if (s < -1e-6 * (1.0 + glm::length(c - eye)))
          ++outside;
        else if (s < 0.0)
          allInside = false;
      }
      if (outside == 8) return 0;
      if (outside > 0) allInside = false;
    }
    return allInside ? 2 : 1;
  }
};

// Adaptive skipping retests a node at least this often.
constexpr int64_t kMaxSkipFrames = 30;

// The draw cost model: the mean time to draw one face with a software
// z-buffer rasterizer at 640x480 (this machine has no GPU): every triangle is
// transformed, clipped against the near plane by rejection, set up and
// filled with a depth test. Measured over four views from the centre of the
// scene's bounds (north, east, south, west), at most 50,000 triangles a
// view, all of them counted, including those the view does not show.
double measureDrawMsPerFace(const Scene& scene) {
  constexpr int kW = 640, kH = 480;
  constexpr size_t kMaxTriangles = 50'000;
  std::vector<float> depth(size_t(kW) * kH);
  const glm::vec3 centre = scene.bounds().empty() ? glm::vec3(0.0f) : scene.bounds().center();
  const glm::mat4 projection =
      glm::perspective(glm::radians(45.0f), float(kW) / float(kH), 0.1f, 1e5f);
  size_t triangles = 0;
  std::vector<uint32_t> faceIds;
  Stopwatch clock;
  for (int view = 0; view < 4; ++view) {
    std::fill(depth.begin(), depth.end(), 1.0f);
    const float yaw = float(view) * 1.5707964f;
    const glm::mat4 m =
        projection * glm::lookAt(centre, centre + glm::vec3(-std::sin(yaw), 0.0f, -std::cos(yaw)),
                                 glm::vec3(0.0f, 1.0f, 0.0f));
    size_t drawn = 0;
    for (const Object& o : scene.objects) {
      for (size_t t = 0; t < o.mesh.triangles.size() && drawn < kMaxTriangles; ++t, ++drawn) {
        if (view == 0) faceIds.push_back(o.mesh.faceIds[t]);
        glm::vec3 sp[3];
        bool behind = false;
        for (int k = 0; k < 3; ++k) {
          const glm::vec4 c = m * glm::vec4(o.mesh.positions[o.mesh.triangles[t][k]], 1.0f);
          if (c.w < 0.1f) behind = true;
          sp[k] =
              glm::vec3((c.x / c.w * 0.5f + 0.5f) * kW, (c.y / c.w * 0.5f + 0.5f) * kH, c.z / c.w);
        }
        if (behind) continue;
        const float area =
            (sp[1].x - sp[0].x) * (sp[2].y - sp[0].y) - (sp[2].x - sp[0].x) * (sp[1].y - sp[0].y);
        if (!(std::abs(area) > 1e-12f)) continue;
        const int x0 = std::max(0, int(std::floor(std::min({sp[0].x, sp[1].x, sp[2].x}))));
        const int x1 = std::min(kW - 1, int(std::ceil(std::max({sp[0].x, sp[1].x, sp[2].x}))));
        const int y0 = std::max(0, int(std::floor(std::min({sp[0].y, sp[1].y, sp[2].y}))));
        const int y1 = std::min(kH - 1, int(std::ceil(std::max({sp[0].y, sp[1].y, sp[2].y}))));
        const float inv = 1.0f / area;
        for (int y = y0; y <= y1; ++y)
          for (int x = x0; x <= x1; ++x) {
            const float px = float(x) + 0.5f, py = float(y) + 0.5f;
            const float w0 =
                ((sp[2].x - sp[1].x) * (py - sp[1].y) - (sp[2].y - sp[1].y) * (px - sp[1].x)) * inv;
            const float w1 =
                ((sp[0].x - sp[2].x) * (py - sp[2].y) - (sp[0].y - sp[2].y) * (px - sp[2].x)) * inv;
            const float w2 = 1.0f - w0 - w1;
            if (w0 < 0.0f || w1 < 0.0f || w2 < 0.0f) continue;
            const float z = w0 * sp[0].z + w1 * sp[1].z + w2 * sp[2].z;
            float& d = depth[size_t(y) * kW + size_t(x)];
            if (z < d) d = z;
          }
      }
      if (drawn >= kMaxTriangles) break;
    }
    triangles += drawn;
  }
  const double ms = clock.ms();
  std::sort(faceIds.begin(), faceIds.end());
  const size_t faces = size_t(std::unique(faceIds.begin(), faceIds.end()) - faceIds.begin());
  // Per face: the time per triangle times the triangles per face.
  if (triangles == 0 || faces == 0) return 0.0;
  return ms / double(triangles) * double(triangles / 4) / double(faces) +
         (depth[0] < -1e30f ? 1e-12 : 0.0);
}

}  // namespace

CullingScene::CullingScene(const Scene& scene) : scene_(scene) {
  tree_ = KdTree::buildOverObjects(scene);
  // Candidate occluders: convex planar faces of static objects, 1 m^2 or larger.
  for (const Object& o : scene.objects) {
    if (o.dynamic) continue;
    std::map<uint32_t, std::pair<std::vector<glm::dvec3>, double>> faces;
    for (size_t t = 0; t < o.mesh.triangles.size(); ++t) {
      auto& [verts, area] = faces[o.mesh.faceIds[t]];
      glm::dvec3 p[3];
      for (int k = 0; k < 3; ++k) {
        p[k] = glm::dvec3(o.mesh.positions[o.mesh.triangles[t][k]]);
        if (std::find(verts.begin(), verts.end(), p[k]) == verts.end()) verts.push_back(p[k]);
      }
      area += 0.5 * glm::length(glm::cross(p[1] - p[0], p[2] - p[0]));
    }
    for (const auto& [id, face] : faces) {
      if (face.second < 1.0) continue;
      auto outline = convexFaceOutline(face.first, face.second);
      if (!outline.empty()) candidates_.push_back(OccluderPolygon{std::move(outline)});
    }
  }
  for (const OccluderPolygon& p : candidates_) {
    glm::dvec3 c(0.0), n(0.0);
    for (const glm::dvec3& v : p.vertices) c += v;
    c /= double(p.vertices.size());
    for (size_t i = 0; i < p.vertices.size(); ++i)
      n += glm::cross(p.vertices[i] - c, p.vertices[(i + 1) % p.vertices.size()] - c);
    const double twiceArea = glm::length(n);
    shapes_.push_back({c, n / twiceArea, 0.5 * twiceArea});
  }
  // Faces per node: leaves sum their objects' faces, interior nodes their children's.
  std::vector<size_t> objectFaces(scene.objects.size());
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    std::vector<uint32_t> ids = scene.objects[i].mesh.faceIds;
    std::sort(ids.begin(), ids.end());
    objectFaces[i] = size_t(std::unique(ids.begin(), ids.end()) - ids.begin());
  }
  nodeFaces_.assign(tree_.nodes().size(), 0);
  for (size_t n = tree_.nodes().size(); n-- > 0;) {
    const KdNode& node = tree_.node(int32_t(n));
    if (node.isLeaf()) {
      for (uint32_t item : tree_.items(int32_t(n))) nodeFaces_[n] += objectFaces[item];
    } else {
      nodeFaces_[n] = nodeFaces_[size_t(node.children[0])] + nodeFaces_[size_t(node.children[1])];
    }
  }
  // Face shares: an object's faces split evenly among the leaves holding it,
  // summed over the subtree.
  std::vector<uint32_t> leavesHolding(scene.objects.size(), 0);
  for (size_t n = 0; n < tree_.nodes().size(); ++n)
    for (uint32_t item : tree_.items(int32_t(n))) ++leavesHolding[item];
  faceShare_.assign(tree_.nodes().size(), 0.0);
  for (size_t n = 0; n < tree_.nodes().size(); ++n)
    for (uint32_t item : tree_.items(int32_t(n)))
      faceShare_[n] += double(objectFaces[item]) / double(leavesHolding[item]);
  // Children come after their parent in the depth-first layout.
  for (size_t n = tree_.nodes().size(); n-- > 1;)
    faceShare_[size_t(tree_.node(int32_t(n)).parent)] += faceShare_[n];
}

double CullingScene::drawMsPerFace() const {
  std::call_once(drawCostOnce_, [this] { drawMsPerFace_ = measureDrawMsPerFace(scene_); });
  return drawMsPerFace_;
}

std::vector<size_t> CullingScene::bestOccluders(const glm::dvec3& viewpoint, size_t k) const {
  std::vector<std::pair<double, size_t>> scored;
  scored.reserve(shapes_.size());
  for (size_t i = 0; i < shapes_.size(); ++i) {
    const CandidateShape& c = shapes_[i];
    const glm::dvec3 v = c.centroid - viewpoint;
    const double along = std::abs(glm::dot(c.normal, v));
    // Edge-on (the viewpoint within rounding of the plane): no shadow.
    if (!(along > 1e-7 * (1.0 + glm::length(c.centroid) + glm::length(viewpoint)))) continue;
    const double d2 = glm::dot(v, v);
    scored.emplace_back(c.area * along / (d2 * std::sqrt(d2)), i);
  }
  const size_t n = std::min(k, scored.size());
  std::partial_sort(scored.begin(), scored.begin() + std::ptrdiff_t(n), scored.end(),
                    [](const auto& a, const auto& b) {
                      return a.first > b.first || (a.first == b.first && a.second < b.second);
                    });
  std::vector<size_t> chosen(n);
  for (size_t i = 0; i < n; ++i) chosen[i] = scored[i].second;
  return chosen;
}

CullingViewer::CullingViewer(const CullingScene& scene, const CullingOptions& options)
    : scene_(scene), options_(options), state_(scene.tree().nodes().size()), rng_(options.seed) {
  // Adaptive skipping weighs drawing costs: measure them now, not inside a frame's timing.
  if (options_.method == CullingMethod::Adaptive) (void)scene_.drawMsPerFace();
}

namespace {

bool closedBoxesMeet(const Box3f& a, const Box3f& b) {
  return a.lo.x <= b.hi.x && b.lo.x <= a.hi.x && a.lo.y <= b.hi.y && b.lo.y <= a.hi.y &&
         a.lo.z <= b.hi.z && b.lo.z <= a.hi.z;
}

}  // namespace

// Visibility propagation, and why its answers are exact consequences of the
// facts it combines. Let the eye e lie outside the closed box B of node N.
// A front face of B is one whose plane strictly separates e from B's
// interior (e.x < lo.x for the -X face, and so on). For any point p of B the
// segment e->p first meets B at a point q of some front face F (B is convex
// and e is outside it). The rope of N across F leads to a node U whose closed
// box contains F, or, if U was not visited this frame, to the ancestor of U
// that was; the facts of that node, or of its descendants meeting F, cover F.
//  - If every front face is covered by hidden boxes, e->q crosses an occluder
//    for every p, so e->p does: N is hidden.
//  - If every front face is covered by lit boxes, e->q crosses none, and q->p
//    lies inside B, which no selected occluder reaches into: N is lit.
// Facts are only ever taken from this frame's occlusion tree, so the answers
// agree with what the tree would say of N whenever the tree is exact.
CullingViewer::Fact CullingViewer::subtreeFact(int32_t node, const Box3f& faceBox) const {
  const NodeState& s = state_[size_t(node)];
  if (s.frame != frame_) return Fact::Unknown;
  if (s.fact != Fact::Unknown) return s.fact;
  const KdNode& kn = scene_.tree().node(node);
  // Only a node opened this frame has children classified this frame.
  if (kn.isLeaf() || s.visibility != NodeVisibility::PartiallyVisible) return Fact::Unknown;
  Fact combined = Fact::Unknown;
  for (int32_t child : kn.children) {
    if (!closedBoxesMeet(scene_.tree().node(child).box, faceBox)) continue;
    const Fact f = subtreeFact(child, faceBox);
    if (f == Fact::Unknown || (combined != Fact::Unknown && f != combined)) return Fact::Unknown;
    combined = f;
  }
  return combined;
}

CullingViewer::Fact CullingViewer::faceFact(int32_t node, KdFace face, const Box3f& faceBox) const {
  int32_t u = scene_.tree().rope(node, face);
  // Lazy propagation (the paper's Figure 7): a neighbour below this frame's
  // termination nodes takes the classification of the termination node.
  while (u >= 0 && state_[size_t(u)].frame != frame_) u = scene_.tree().node(u).parent;
  if (u < 0) return Fact::Unknown;
  return subtreeFact(u, faceBox);
}

// One frame of culling (Figure 4 and its variants), as named steps over the
// viewer's per-node state. Built and run by CullingViewer::frame.
struct CullingFrame {
  using Fact = CullingViewer::Fact;
  using NodeState = CullingViewer::NodeState;

  CullingViewer& viewer;
  const KdTree& tree;
  const glm::dvec3 eye;
  const CullingMethod method;
  const bool updating;     // hierarchy updating (every method but the classical one)
  const bool propagating;  // visibility propagation (C, D, adaptive)
  const bool adaptive;
  Frustum frustum;
  std::vector<OccluderPolygon> occluders;
  std::vector<Box3f> occluderBoxes;  // for propagation's "no occluder reaches into the box"
  std::optional<OcclusionTree> occlusion;
  std::uniform_real_distribution<double> uniform{0.0, 1.0};
  FrameResult result;

  CullingFrame(CullingViewer& v, const glm::dvec3& e)
      : viewer(v),
        tree(v.scene_.tree()),
        eye(e),
        method(v.options_.method),
        updating(method != CullingMethod::Classical),
        propagating(method == CullingMethod::Propagation || method == CullingMethod::Conservative ||
                    method == CullingMethod::Adaptive),
        adaptive(method == CullingMethod::Adaptive) {}

  // View frustum: |d.r| <= th (d.f) and |d.u| <= tv (d.f).
  void setUpFrustum(double yawDeg, double pitchDeg) {
    const glm::dvec3 f = viewDirection(yawDeg, pitchDeg);
    glm::dvec3 r = glm::cross(f, glm::dvec3(0, 1, 0));
    if (glm::length(r) < 1e-9) r = glm::dvec3(1, 0, 0);
    r = glm::normalize(r);
    const glm::dvec3 u = glm::cross(r, f);
    const double th = std::tan(viewer.options_.fovDeg * 0.5 * 3.14159265358979323846 / 180.0),
                 tv = th / viewer.options_.aspect;
    frustum = Frustum{eye, {th * f - r, th * f + r, tv * f - u, tv * f + u}};
  }

  // The occlusion tree of the k best occluders for this viewpoint.
  void buildOcclusionTree() {
    const auto& candidates = viewer.scene_.occluderCandidates();
    const std::vector<size_t> chosen = viewer.scene_.bestOccluders(eye, viewer.options_.occluders);
    occluders.reserve(chosen.size());
    for (size_t i : chosen) {
      occluders.push_back(candidates[i]);
      Box3f b;
      for (const glm::dvec3& v : candidates[i].vertices) {
        // Rounded outward, and widened by far more than the rounding of float boxes.
        const glm::vec3 lo(v - glm::dvec3(1e-4 * (1.0 + glm::length(v)))),
            hi(v + glm::dvec3(1e-4 * (1.0 + glm::length(v))));
        b.extend(lo);
        b.extend(hi);
      }
      occluderBoxes.push_back(b);
    }
    occlusion.emplace(eye, occluders);
  }

  void markSubtree(int32_t node) {
    std::vector<int32_t> stack{node};
    while (!stack.empty()) {
      const int32_t n = stack.back();
      stack.pop_back();
      const KdNode& kn = tree.node(n);
      if (kn.isLeaf())
        result.leafVisible[size_t(n)] = 1;
      else
        stack.insert(stack.end(), {kn.children[0], kn.children[1]});
    }
  }

  // Visibility propagation for node n (see the proof above); Unknown when it fails.
  Fact propagate(int32_t n) const {
    const Box3f& b = tree.node(n).box;
    Fact combined = Fact::Unknown;
    bool anyFace = false;
    for (int axis = 0; axis < 3; ++axis) {
      const double e = eye[axis];
      bool high;
      if (e < double(b.lo[axis]))
        high = false;
      else if (e > double(b.hi[axis]))
        high = true;
      else
        continue;
      anyFace = true;
      Box3f faceBox = b;
      faceBox.lo[axis] = faceBox.hi[axis] = high ? b.hi[axis] : b.lo[axis];
      const Fact fact = viewer.faceFact(n, KdFace(kdFace(axis, high)), faceBox);
      if (fact == Fact::Unknown || (combined != Fact::Unknown && fact != combined))
        return Fact::Unknown;
      combined = fact;
    }
    if (!anyFace) return Fact::Unknown;  // the eye is in the box
    if (combined == Fact::Lit)
      for (const Box3f& ob : occluderBoxes)
        if (closedBoxesMeet(ob, b)) return Fact::Unknown;
    return combined;
  }

  // Adaptive: after a test or a propagation, count whether the node turned
  // less visible since its last classification, and over how many frames.
  void learn(NodeState& s, NodeVisibility previous, bool wasTermination) {
    const int64_t frame = viewer.frame_;
    if (adaptive && wasTermination && s.classifiedFrame > 0) {
      const double changed = s.visibility < previous ? 1.0 : 0.0,
                   frames = double(frame - s.classifiedFrame);
      s.changes = 0.8f * s.changes + float(changed);
      s.span = 0.8f * s.span + float(frames);
      viewer.changes_ = 0.995 * viewer.changes_ + changed;
      viewer.span_ = 0.995 * viewer.span_ + frames;
    }
    s.classifiedFrame = frame;
  }

  // A node only partly in the frustum is at most partially visible, so that
  // its children get frustum-culled whichever node the traversal classifies.
  static NodeVisibility demote(NodeVisibility v, int inFrustum, const KdNode& kn) {
    return v == NodeVisibility::Visible && inFrustum == 1 && !kn.isLeaf()
               ? NodeVisibility::PartiallyVisible
               : v;
  }

  // Propagation, tried with probability pVp (always after a success last
  // frame); true when it classified the node.
  bool tryPropagation(int32_t n, NodeState& s, NodeVisibility previous, bool wasTermination,
                      int inFrustum) {
    if (!propagating || previous == NodeVisibility::PartiallyVisible) return false;
    const int64_t frame = viewer.frame_;
    const bool succeededLastFrame = s.propagatedFrame == frame - 1;
    const double p =
        adaptive ? std::clamp(double(s.propagationRate), 0.05, 1.0) : viewer.options_.pVp;
    if (!succeededLastFrame && !(uniform(viewer.rng_) < p)) return false;
    ++result.propagationTries;
    const Fact fact = propagate(n);
    if (adaptive)
      s.propagationRate = 0.7f * s.propagationRate + (fact != Fact::Unknown ? 0.3f : 0.0f);
    if (fact == Fact::Unknown) return false;
    ++result.propagated;
    s.propagatedFrame = frame;
    s.fact = fact;
    s.visibility =
        demote(fact == Fact::Hidden ? NodeVisibility::Invisible : NodeVisibility::Visible,
               inFrustum, tree.node(n));
    learn(s, previous, wasTermination);
    return true;
  }

  // Conservative hierarchy updating: a node visible last frame (or a
  // partially visible leaf) is assumed to stay visible; true when skipped.
  bool trySkip(int32_t n, NodeState& s, NodeVisibility previous, bool wasTermination) {
    const KdNode& kn = tree.node(n);
    if (!(method == CullingMethod::Conservative || adaptive) || !wasTermination ||
        previous == NodeVisibility::Invisible ||
        !(kn.isLeaf() || previous == NodeVisibility::Visible))
      return false;
    double p = viewer.options_.pSkip;
    if (adaptive) {
      // Skip while the expected cost of drawing the node in vain is below
      // a test's: the chance it turned less visible in the frames since
      // its last classification, from its rate blended with all nodes'.
      const int64_t sinceClassified = viewer.frame_ - s.classifiedFrame;
      const double prior = (viewer.changes_ + 0.01) / (viewer.span_ + 0.1);
      const double rate = (double(s.changes) + 2.0 * prior) / (double(s.span) + 2.0);
      const double chance = std::min(1.0, rate * double(sinceClassified));
      const double waste = chance * viewer.scene_.faceShare(n) * viewer.scene_.drawMsPerFace();
      // A node is retested at least every kMaxSkipFrames frames, whatever the estimates say.
      p = viewer.testMs_ > 0.0 && waste < viewer.testMs_ && sinceClassified < kMaxSkipFrames ? 1.0
                                                                                             : 0.0;
    }
    if (!(uniform(viewer.rng_) < p)) return false;
    s.visibility = NodeVisibility::Visible;
    ++result.skipped;
    return true;
  }

  // The occlusion-tree test; adaptive culling times every 8th one.
  NodeVisibility testOcclusion(const KdNode& kn) {
    ++result.nodeTests;
    if (!adaptive || (result.nodeTests & 7) != 1) return occlusion->classify(kn.box);
    Stopwatch testClock;
    const NodeVisibility v = occlusion->classify(kn.box);
    // Winsorized: a test the scheduler interrupted must not make every
    // later skip look cheap.
    double& testMs = viewer.testMs_;
    const double ms = testMs > 0.0 ? std::min(testClock.ms(), 2.0 * testMs) : testClock.ms();
    testMs = testMs > 0.0 ? 0.95 * testMs + 0.05 * ms : ms;
    return v;
  }

  // Classifies termination node n: frustum, small-node rule, propagation,
  // conservative skipping, occlusion-tree test.
  void classify(int32_t n, NodeState& s) {
    const KdNode& kn = tree.node(n);
    const NodeVisibility previous = s.visibility;
    const bool wasTermination = s.frame == viewer.frame_ - 1;
    s.fact = Fact::Unknown;
    const int inFrustum = frustum.classify(kn.box);
    if (inFrustum == 0) {
      s.visibility = NodeVisibility::Invisible;
      return;
    }
    if (viewer.scene_.nodeFaces(n) <= viewer.options_.smallNodeFaces) {
      s.visibility = inFrustum == 2 || kn.isLeaf() ? NodeVisibility::Visible
                                                   : NodeVisibility::PartiallyVisible;
      return;
    }
    if (tryPropagation(n, s, previous, wasTermination, inFrustum)) return;
    if (trySkip(n, s, previous, wasTermination)) return;
    const NodeVisibility v = testOcclusion(kn);
    s.fact = v == NodeVisibility::Invisible ? Fact::Hidden
             : v == NodeVisibility::Visible ? Fact::Lit
                                            : Fact::Unknown;
    s.visibility = demote(v, inFrustum, kn);
    learn(s, previous, wasTermination);
  }

  // Figure 4 (hierarchy updating); with `updating` false it is the classical
  // algorithm, which classifies every node it reaches.
  void visit(int32_t n) {
    NodeState& s = viewer.state_[size_t(n)];
    const KdNode& kn = tree.node(n);
    const size_t smallNode = viewer.options_.smallNodeFaces;
    // A node with a small child is never skipped: the small child would be
    // drawn without a test, which is only right while this node really is
    // partially visible, and only a test of this node can tell.
    const bool smallChild = !kn.isLeaf() && (viewer.scene_.nodeFaces(kn.children[0]) <= smallNode ||
                                             viewer.scene_.nodeFaces(kn.children[1]) <= smallNode);
    const bool termination = kn.isLeaf() || s.visibility != NodeVisibility::PartiallyVisible ||
                             s.frame < viewer.frame_ - 1 || smallChild;
    if (!updating || termination)
      classify(n, s);
    else
      s.fact = Fact::Unknown;  // opened node: its fact is pulled up from its children
    s.frame = viewer.frame_;
    switch (s.visibility) {
      case NodeVisibility::Visible:
        markSubtree(n);
        break;
      case NodeVisibility::PartiallyVisible:
        if (kn.isLeaf()) {
          result.leafVisible[size_t(n)] = 1;
        } else {
          // Front to back: the child on the eye's side of the split first.
          const int first = eye[kn.axis] > double(kn.split) ? 1 : 0;
          visit(kn.children[size_t(first)]);
          visit(kn.children[size_t(1 - first)]);
          const NodeState& a = viewer.state_[size_t(kn.children[0])];
          const NodeState& b = viewer.state_[size_t(kn.children[1])];
          if (updating && a.visibility == b.visibility) s.visibility = a.visibility;  // pull-up
          if (s.fact == Fact::Unknown && a.fact == b.fact) s.fact = a.fact;
        }
        break;
      case NodeVisibility::Invisible:
        break;
    }
  }

  // The faces of every object in a visible leaf (the renderer's work, not
  // timed as culling).
  void gatherFaces(bool keepFaces) {
    const Scene& scene = viewer.scene_.scene();
    std::vector<uint8_t> objectSeen(scene.objects.size(), 0);
    for (size_t n = 0; n < result.leafVisible.size(); ++n) {
      if (!result.leafVisible[n]) continue;
      ++result.visibleLeaves;
      for (uint32_t item : tree.items(int32_t(n))) objectSeen[item] = 1;
    }
    std::vector<uint32_t> faces;
    for (size_t o = 0; o < objectSeen.size(); ++o)
      if (objectSeen[o])
        faces.insert(faces.end(), scene.objects[o].mesh.faceIds.begin(),
                     scene.objects[o].mesh.faceIds.end());
    std::sort(faces.begin(), faces.end());
    faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
    result.visibleFaces = faces.size();
    if (keepFaces) result.faces = std::move(faces);
  }
};

FrameResult CullingViewer::frame(const glm::dvec3& eye, double yawDeg, double pitchDeg) {
  Stopwatch clock;
  ++frame_;
  CullingFrame f(*this, eye);
  f.setUpFrustum(yawDeg, pitchDeg);
  f.buildOcclusionTree();
  f.result.leafVisible.assign(scene_.tree().nodes().size(), 0);
  f.visit(KdTree::root());
  // Culling ends here; gathering the faces to draw is the renderer's work.
  f.result.cullingMs = clock.ms();
  f.gatherFaces(options_.collectFaces);
  return std::move(f.result);
}

}  // namespace vistream
