// Bittner and Havran 2001, "Exploiting coherence in hierarchical visibility
// algorithms": the classical hierarchical culling (section "Classical
// Approach"), hierarchy updating with pull-up (Figure 4) and conservative
// hierarchy updating (section "Conservative Hierarchy Updating").
#include "server/visibility/hierarchical_culling.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>

#include "common/core/error.h"
#include "common/core/timer.h"
#include "common/generate/path.h"

namespace vistream {

CullingMethod parseCullingMethod(const std::string& name) {
  if (name == "A") return CullingMethod::Classical;
  if (name == "B") return CullingMethod::HierarchyUpdating;
  if (name == "D") return CullingMethod::Conservative;
  if (name == "C" || name == "adaptive")
    throwInputError("--method {}: visibility propagation (C) and adaptive probabilities are not implemented yet", name);
  throwInputError("--method: expected A, B or D, got '{}'", name);
}

const char* cullingMethodName(CullingMethod m) {
  switch (m) {
    case CullingMethod::Classical: return "A";
    case CullingMethod::HierarchyUpdating: return "B";
    case CullingMethod::Conservative: return "D";
  }
  return "?";
}

namespace {

// Convex planar outline of a face, shrunk slightly towards its centre so that
// float noise can never make it larger than the geometry; empty if the face
// is not planar and convex.
std::vector<glm::dvec3> convexFaceOutline(const std::vector<glm::dvec3>& verts, double triangleArea) {
  if (verts.size() < 3) return {};
  glm::dvec3 c(0.0);
  for (const auto& v : verts) c += v;
  c /= double(verts.size());
  glm::dvec3 n(0.0);
  for (size_t i = 0; i < verts.size(); ++i) n += glm::cross(verts[i] - c, verts[(i + 1) % verts.size()] - c);
  if (!(glm::length(n) > 0.0)) return {};
  n = glm::normalize(n);
  const glm::dvec3 u = glm::normalize(std::abs(n.x) < 0.9 ? glm::cross(n, glm::dvec3(1, 0, 0)) : glm::cross(n, glm::dvec3(0, 1, 0)));
  const glm::dvec3 w = glm::cross(n, u);
  double mag = 0.0;
  for (const auto& v : verts) {
    if (std::abs(glm::dot(v - c, n)) > 1e-4 * (1.0 + glm::length(v - c))) return {};  // not planar
    mag = std::max(mag, glm::length(v));
  }
  // Angular order around the centre, then check convexity and area.
  std::vector<size_t> order(verts.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    const glm::dvec3 da = verts[a] - c, db = verts[b] - c;
    return std::atan2(glm::dot(da, w), glm::dot(da, u)) < std::atan2(glm::dot(db, w), glm::dot(db, u));
  });
  double area = 0.0;
  for (size_t i = 0; i < order.size(); ++i) {
    const glm::dvec3 a = verts[order[i]] - c, b = verts[order[(i + 1) % order.size()]] - c;
    area += 0.5 * glm::dot(glm::cross(a, b), n);
    const glm::dvec3 nxt = verts[order[(i + 2) % order.size()]] - c;
    if (glm::dot(glm::cross(b - a, nxt - b), n) < -1e-9 * (1.0 + mag * mag)) return {};  // reflex corner
  }
  if (std::abs(area - triangleArea) > 1e-6 * (1.0 + area)) return {};  // holes or overlaps
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
        const glm::dvec3 c((k & 1) ? b.hi.x : b.lo.x, (k & 2) ? b.hi.y : b.lo.y, (k & 4) ? b.hi.z : b.lo.z);
        const double s = glm::dot(c - eye, n);
        if (s < -1e-6 * (1.0 + glm::length(c - eye))) ++outside;
        else if (s < 0.0) allInside = false;
      }
      if (outside == 8) return 0;
      if (outside > 0) allInside = false;
    }
    return allInside ? 2 : 1;
  }
};

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
  // Draw cost model: transform and bound every triangle (up to 200k) once.
  const glm::mat4 m(0.9f, 0.1f, 0.0f, 0.0f, -0.1f, 0.9f, 0.1f, 0.0f, 0.0f, -0.1f, 0.9f, 0.01f, 1.0f, 2.0f, 3.0f, 1.0f);
  size_t tris = 0;
  Stopwatch clock;
  float sink = 0.0f;
  for (const Object& o : scene.objects) {
    for (const glm::uvec3& t : o.mesh.triangles) {
      glm::vec2 lo(1e30f), hi(-1e30f);
      for (int k = 0; k < 3; ++k) {
        const glm::vec4 p = m * glm::vec4(o.mesh.positions[t[k]], 1.0f);
        const glm::vec2 s = glm::vec2(p) / std::max(p.w, 1e-6f);
        lo = glm::min(lo, s);
        hi = glm::max(hi, s);
      }
      sink += hi.x - lo.x + hi.y - lo.y;
      if (++tris >= 200'000) break;
    }
    if (tris >= 200'000) break;
  }
  drawMsPerFace_ = tris ? clock.ms() / double(tris) + (sink == 12345.0f ? 1e-12 : 0.0) : 0.0;
}

CullingViewer::CullingViewer(const CullingScene& scene, const CullingOptions& options)
    : scene_(scene), options_(options), state_(scene.tree().nodes().size()), rng_(options.seed) {}

FrameResult CullingViewer::frame(const glm::dvec3& eye, double yawDeg, double pitchDeg) {
  Stopwatch clock;
  FrameResult result;
  ++frame_;
  const KdTree& tree = scene_.tree();

  // View frustum: |d.r| <= th (d.f) and |d.u| <= tv (d.f).
  const glm::dvec3 f = viewDirection(yawDeg, pitchDeg);
  glm::dvec3 r = glm::cross(f, glm::dvec3(0, 1, 0));
  if (glm::length(r) < 1e-9) r = glm::dvec3(1, 0, 0);
  r = glm::normalize(r);
  const glm::dvec3 u = glm::cross(r, f);
  const double th = std::tan(options_.fovDeg * 0.5 * 3.14159265358979323846 / 180.0), tv = th / options_.aspect;
  const Frustum frustum{eye, {th * f - r, th * f + r, tv * f - u, tv * f + u}};

  // The occlusion tree of the k best occluders for this viewpoint.
  const auto& candidates = scene_.occluderCandidates();
  const std::vector<size_t> chosen = selectOccluders(eye, candidates, options_.occluders);
  std::vector<OccluderPolygon> occluders;
  occluders.reserve(chosen.size());
  for (size_t i : chosen) occluders.push_back(candidates[i]);
  const OcclusionTree occlusion(eye, occluders);

  result.leafVisible.assign(tree.nodes().size(), 0);
  auto markSubtree = [&](int32_t node) {
    std::vector<int32_t> stack{node};
    while (!stack.empty()) {
      const int32_t n = stack.back();
      stack.pop_back();
      const KdNode& kn = tree.node(n);
      if (kn.isLeaf()) result.leafVisible[size_t(n)] = 1;
      else stack.insert(stack.end(), {kn.children[0], kn.children[1]});
    }
  };
  // The node test: frustum, small-node rule, then the occlusion tree. A node
  // only partly in the frustum is at most partially visible, so that its
  // children get frustum-culled whichever node the traversal tests.
  auto test = [&](int32_t n) {
    const KdNode& kn = tree.node(n);
    const int inFrustum = frustum.classify(kn.box);
    if (inFrustum == 0) return NodeVisibility::Invisible;
    if (scene_.nodeFaces(n) <= options_.smallNodeFaces)
      return inFrustum == 2 || kn.isLeaf() ? NodeVisibility::Visible : NodeVisibility::PartiallyVisible;
    ++result.nodeTests;
    NodeVisibility v = occlusion.classify(kn.box);
    if (v == NodeVisibility::Visible && inFrustum == 1 && !kn.isLeaf()) v = NodeVisibility::PartiallyVisible;
    return v;
  };

  const bool updating = options_.method != CullingMethod::Classical;
  std::bernoulli_distribution skip(options_.pSkip);
  // Figure 4 (hierarchy updating); with `updating` false it is the classical
  // algorithm, which tests every node it reaches.
  auto visit = [&](auto&& self, int32_t n) -> void {
    NodeState& s = state_[size_t(n)];
    const KdNode& kn = tree.node(n);
    // A node with a small child is never skipped: the small child would be
    // drawn without a test, which is only right while this node really is
    // partially visible, and only a test of this node can tell.
    const bool smallChild = !kn.isLeaf() && (scene_.nodeFaces(kn.children[0]) <= options_.smallNodeFaces ||
                                             scene_.nodeFaces(kn.children[1]) <= options_.smallNodeFaces);
    const bool termination = kn.isLeaf() || s.visibility != NodeVisibility::PartiallyVisible ||
                             s.frame < frame_ - 1 || smallChild;
    if (!updating || termination) {
      if (options_.method == CullingMethod::Conservative && s.frame == frame_ - 1 &&
          s.visibility != NodeVisibility::Invisible && (kn.isLeaf() || s.visibility == NodeVisibility::Visible) &&
          skip(rng_)) {
        s.visibility = NodeVisibility::Visible;  // conservative: assume it stayed visible
        ++result.skipped;
      } else {
        s.visibility = test(n);
      }
    }
    s.frame = frame_;
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
          self(self, kn.children[size_t(first)]);
          self(self, kn.children[size_t(1 - first)]);
          const NodeVisibility a = state_[size_t(kn.children[0])].visibility;
          const NodeVisibility b = state_[size_t(kn.children[1])].visibility;
          if (updating && a == b) s.visibility = a;  // pull-up
        }
        break;
      case NodeVisibility::Invisible:
        break;
    }
  };
  visit(visit, KdTree::root());
  // Culling ends here; gathering the faces to draw is the renderer's work.
  result.cullingMs = clock.ms();

  std::vector<uint8_t> objectSeen(scene_.scene().objects.size(), 0);
  for (size_t n = 0; n < result.leafVisible.size(); ++n) {
    if (!result.leafVisible[n]) continue;
    ++result.visibleLeaves;
    for (uint32_t item : tree.items(int32_t(n))) objectSeen[item] = 1;
  }
  std::vector<uint32_t> faces;
  for (size_t o = 0; o < objectSeen.size(); ++o)
    if (objectSeen[o])
      faces.insert(faces.end(), scene_.scene().objects[o].mesh.faceIds.begin(), scene_.scene().objects[o].mesh.faceIds.end());
  std::sort(faces.begin(), faces.end());
  faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
  result.visibleFaces = faces.size();
  if (options_.collectFaces) result.faces = std::move(faces);
  return result;
}

}  // namespace vistream
