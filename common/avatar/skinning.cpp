#include "common/avatar/skinning.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <glm/gtc/matrix_transform.hpp>
#include <map>
#include <tuple>

#include "common/core/check.h"
#include "common/core/error.h"

namespace vistream {
namespace {

glm::quat toQuat(const glm::vec4& v) {
  return glm::quat(v.w, v.x, v.y, v.z);  // glm: (w, x, y, z)
}
glm::vec4 fromQuat(const glm::quat& q) {
  return {q.x, q.y, q.z, q.w};
}

// Spherical linear interpolation along the shorter arc.
glm::vec4 slerp(const glm::vec4& a, const glm::vec4& b, float s) {
  glm::quat qa = glm::normalize(toQuat(a)), qb = glm::normalize(toQuat(b));
  if (glm::dot(qa, qb) < 0.0f) qb = -qb;
  return fromQuat(glm::normalize(glm::slerp(qa, qb, s)));
}

glm::mat4 localMatrix(const glm::vec3& t, const glm::vec4& r, const glm::vec3& s) {
  const glm::mat4 translate = glm::translate(glm::mat4(1.0f), t);
  const glm::mat4 rotate = glm::mat4_cast(glm::normalize(toQuat(r)));
  return translate * rotate * glm::scale(glm::mat4(1.0f), s);
}

}  // namespace

glm::vec4 sampleChannel(const AnimationChannel& c, float t) {
  const size_t keys = c.times.size();
  const bool cubic = c.interpolation == AnimationChannel::Interpolation::CubicSpline;
  const bool rotation = c.path == AnimationChannel::Path::Rotation;
  if (keys == 0 || c.values.size() < (cubic ? 3 * keys : keys)) return {0, 0, 0, 1};
  auto value = [&](size_t k) { return cubic ? c.values[3 * k + 1] : c.values[k]; };
  if (!(t > c.times.front())) return value(0);  // NaN too
  if (t >= c.times.back()) return value(keys - 1);
  const size_t k1 = size_t(std::upper_bound(c.times.begin(), c.times.end(), t) - c.times.begin());
  const size_t k0 = k1 - 1;
  const float dt = c.times[k1] - c.times[k0];
  const float s = dt > 0.0f ? (t - c.times[k0]) / dt : 0.0f;
  switch (c.interpolation) {
    case AnimationChannel::Interpolation::Step:
      return value(k0);
    case AnimationChannel::Interpolation::Linear:
      return rotation ? slerp(value(k0), value(k1), s) : value(k0) + (value(k1) - value(k0)) * s;
    case AnimationChannel::Interpolation::CubicSpline: {
      // Hermite: p0, out-tangent of k0, p1, in-tangent of k1 (scaled by dt).
      const glm::vec4 p0 = value(k0), m0 = c.values[3 * k0 + 2] * dt;
      const glm::vec4 p1 = value(k1), m1 = c.values[3 * k1] * dt;
      const float s2 = s * s, s3 = s2 * s;
      const glm::vec4 p = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 +
                          (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1;
      return rotation ? fromQuat(glm::normalize(toQuat(p))) : p;
    }
  }
  return value(k0);
}

std::vector<glm::mat4> globalNodeMatrices(const Scene& scene, const Animation* animation, float t) {
  const size_t n = scene.nodes.size();
  std::vector<glm::vec3> translation(n), scale(n);
  std::vector<glm::vec4> rotation(n);
  for (size_t i = 0; i < n; ++i) {
    translation[i] = scene.nodes[i].translation;
    rotation[i] = scene.nodes[i].rotation;
    scale[i] = scene.nodes[i].scale;
  }
  if (animation) {
    float time = t;
    if (animation->duration > 0.0f && std::isfinite(t)) {
      time = std::fmod(t, animation->duration);
      if (time < 0.0f) time += animation->duration;
    }
    for (const AnimationChannel& c : animation->channels) {
      if (c.node < 0 || size_t(c.node) >= n) continue;
      const glm::vec4 v = sampleChannel(c, time);
      switch (c.path) {
        case AnimationChannel::Path::Translation:
          translation[size_t(c.node)] = glm::vec3(v);
          break;
        case AnimationChannel::Path::Rotation:
          rotation[size_t(c.node)] = v;
          break;
        case AnimationChannel::Path::Scale:
          scale[size_t(c.node)] = glm::vec3(v);
          break;
      }
    }
  }
  // Parents first: resolve each node by walking up (the loader rejects cycles).
  std::vector<glm::mat4> global(n);
  std::vector<uint8_t> done(n, 0);
  std::vector<size_t> chain;
  for (size_t i = 0; i < n; ++i) {
    chain.clear();
    for (size_t k = i; !done[k];) {
      chain.push_back(k);
      const int32_t p = scene.nodes[k].parent;
      if (p < 0 || size_t(p) >= n || chain.size() > n) break;
      k = size_t(p);
    }
    for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
      const size_t k = *it;
      const glm::mat4 local = localMatrix(translation[k], rotation[k], scale[k]);
      const int32_t p = scene.nodes[k].parent;
      global[k] = p >= 0 && size_t(p) < n && done[size_t(p)] ? global[size_t(p)] * local : local;
      done[k] = 1;
    }
  }
  return global;
}

std::vector<glm::mat4> jointMatrices(const Skin& skin, const std::vector<glm::mat4>& globals) {
  std::vector<glm::mat4> out(skin.joints.size(), glm::mat4(1.0f));
  for (size_t j = 0; j < skin.joints.size(); ++j) {
    const int32_t node = skin.joints[j];
    const glm::mat4 g =
        node >= 0 && size_t(node) < globals.size() ? globals[size_t(node)] : glm::mat4(1.0f);
    out[j] = j < skin.inverseBindMatrices.size() ? g * skin.inverseBindMatrices[j] : g;
  }
  return out;
}

SkinnedMesh SkinnedMesh::firstOf(const Scene& scene) {
  for (const Object& o : scene.objects) {
    if (o.skin < 0 || size_t(o.skin) >= scene.skins.size() || o.mesh.joints.empty()) continue;
    const size_t jointCount = scene.skins[size_t(o.skin)].joints.size();
    SkinnedMesh m;
    m.name = o.name;
    m.skin = o.skin;
    m.positions.reserve(o.mesh.positions.size());
    for (const glm::vec3& p : o.mesh.positions)
      m.positions.push_back(glm::vec3(glm::dvec3(p) + scene.origin));
    m.triangles = o.mesh.triangles;
    m.faceIds = o.mesh.faceIds;
    m.texcoords = o.mesh.texcoords;
    m.materials = o.mesh.materials;
    m.joints = o.mesh.joints;
    m.weights = o.mesh.weights;
    if (m.joints.size() != m.positions.size() || m.weights.size() != m.positions.size())
      throwInputError("{}: object '{}' has {} joint and {} weight entries for {} vertices",
                      scene.name, o.name, m.joints.size(), m.weights.size(), m.positions.size());
    for (size_t v = 0; v < m.positions.size(); ++v) {
      glm::vec4& w = m.weights[v];
      for (int k = 0; k < 4; ++k) {
        if (!(w[k] > 0.0f)) w[k] = 0.0f;
        if (w[k] > 0.0f && m.joints[v][k] >= jointCount)
          throwInputError("{}: object '{}' vertex {} uses joint {} of a skin with {} joints",
                          scene.name, o.name, v, m.joints[v][k], jointCount);
      }
      const float sum = w.x + w.y + w.z + w.w;
      w = sum > 0.0f ? w / sum : glm::vec4(1, 0, 0, 0);  // unweighted: the skin's first joint
    }
    return m;
  }
  throwInputError("{}: no skinned object (a mesh with JOINTS_0 and WEIGHTS_0 under a skin)",
                  scene.name);
}

namespace {

struct SkinWeights {
  glm::u16vec4 joints{0};
  glm::vec4 weights{0.0f};
};

// Equal shares of each skin's weights, merged by joint, the four largest
// kept.
SkinWeights blend(std::initializer_list<SkinWeights> skins) {
  const float share = 1.0f / float(skins.size());
  std::vector<std::pair<uint16_t, float>> w;
  for (const SkinWeights& s : skins)
    for (int k = 0; k < 4; ++k) {
      if (!(s.weights[k] > 0.0f)) continue;
      auto it =
          std::find_if(w.begin(), w.end(), [&](const auto& e) { return e.first == s.joints[k]; });
      if (it == w.end())
        w.emplace_back(s.joints[k], share * s.weights[k]);
      else
        it->second += share * s.weights[k];
    }
  std::sort(w.begin(), w.end(), [](const auto& x, const auto& y) {
    return x.second != y.second ? x.second > y.second : x.first < y.first;
  });
  SkinWeights out;
  float sum = 0.0f;
  for (size_t k = 0; k < std::min<size_t>(4, w.size()); ++k) {
    out.joints[int(k)] = w[k].first;
    out.weights[int(k)] = w[k].second;
    sum += w[k].second;
  }
  out.weights = sum > 0.0f ? out.weights / sum : glm::vec4(1, 0, 0, 0);
  return out;
}

}  // namespace

SkinnedMesh SkinnedMesh::subdivided(int times, Split split) const {
  VS_CHECK(times >= 0 && times <= 6);
  SkinnedMesh out;
  out.name = name;
  out.skin = skin;
  // Weld: one vertex per (position, skin).
  std::map<std::tuple<float, float, float, uint64_t, uint64_t, uint64_t>, uint32_t> welded;
  std::vector<uint32_t> remap(positions.size());
  for (size_t v = 0; v < positions.size(); ++v) {
    uint64_t j = 0, w0 = 0, w1 = 0;
    std::memcpy(&j, &joints[v], sizeof(glm::u16vec4));
    std::memcpy(&w0, &weights[v].x, 8);
    std::memcpy(&w1, &weights[v].z, 8);
    const auto key = std::make_tuple(positions[v].x, positions[v].y, positions[v].z, j, w0, w1);
    const auto [it, added] = welded.emplace(key, uint32_t(out.positions.size()));
    if (added) {
      out.positions.push_back(positions[v]);
      out.joints.push_back(joints[v]);
      out.weights.push_back(weights[v]);
    }
    remap[v] = it->second;
  }
  for (size_t t = 0; t < triangles.size(); ++t) {
    out.triangles.emplace_back(remap[triangles[t].x], remap[triangles[t].y], remap[triangles[t].z]);
    out.materials.push_back(t < materials.size() ? materials[t] : 0u);
  }
  for (int pass = 0; pass < times; ++pass) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> midpoints;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      const auto key = std::minmax(a, b);
      const auto [it, added] = midpoints.emplace(key, uint32_t(out.positions.size()));
      if (added) {
        out.positions.push_back(0.5f * (out.positions[a] + out.positions[b]));
        const SkinWeights s =
            blend({{out.joints[a], out.weights[a]}, {out.joints[b], out.weights[b]}});
        out.joints.push_back(s.joints);
        out.weights.push_back(s.weights);
      }
      return it->second;
    };
    std::vector<glm::uvec3> finer;
    std::vector<uint32_t> finerMaterials;
    if (split == Split::AtCentroids) {
      for (size_t t = 0; t < out.triangles.size(); ++t) {
        const glm::uvec3 c = out.triangles[t];
        const uint32_t m = uint32_t(out.positions.size());
        out.positions.push_back((out.positions[c.x] + out.positions[c.y] + out.positions[c.z]) /
                                3.0f);
        const SkinWeights s = blend({{out.joints[c.x], out.weights[c.x]},
                                     {out.joints[c.y], out.weights[c.y]},
                                     {out.joints[c.z], out.weights[c.z]}});
        out.joints.push_back(s.joints);
        out.weights.push_back(s.weights);
        finer.insert(finer.end(), {{c.x, c.y, m}, {c.y, c.z, m}, {c.z, c.x, m}});
        finerMaterials.insert(finerMaterials.end(), 3, out.materials[t]);
      }
      out.triangles = std::move(finer);
      out.materials = std::move(finerMaterials);
      continue;
    }
    for (size_t t = 0; t < out.triangles.size(); ++t) {
      const glm::uvec3 c = out.triangles[t];
      const uint32_t ab = midpoint(c.x, c.y), bc = midpoint(c.y, c.z), ca = midpoint(c.z, c.x);
      finer.insert(finer.end(), {{c.x, ab, ca}, {ab, c.y, bc}, {ca, bc, c.z}, {ab, bc, ca}});
      finerMaterials.insert(finerMaterials.end(), 4, out.materials[t]);
    }
    out.triangles = std::move(finer);
    out.materials = std::move(finerMaterials);
  }
  return out;
}

void vertexNormals(const std::vector<glm::vec3>& positions,
                   const std::vector<glm::uvec3>& triangles, std::vector<glm::vec3>& normals) {
  normals.assign(positions.size(), glm::vec3(0.0f));
  for (const glm::uvec3& t : triangles) {
    const glm::vec3 n =
        glm::cross(positions[t.y] - positions[t.x], positions[t.z] - positions[t.x]);
    for (int k = 0; k < 3; ++k) normals[t[k]] += n;
  }
  for (glm::vec3& n : normals) {
    const float len = glm::length(n);
    n = len > 0.0f && std::isfinite(len) ? n / len : glm::vec3(0.0f, 1.0f, 0.0f);
  }
}

void poseMesh(const SkinnedMesh& mesh, const std::vector<glm::mat4>& joints, PosedMesh& out) {
  out.positions.resize(mesh.positions.size());
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    glm::mat4 m(0.0f);
    for (int k = 0; k < 4; ++k) {
      const float w = mesh.weights[v][k];
      if (w > 0.0f && mesh.joints[v][k] < joints.size()) m += w * joints[mesh.joints[v][k]];
    }
    out.positions[v] = glm::vec3(m * glm::vec4(mesh.positions[v], 1.0f));
  }
  vertexNormals(out.positions, mesh.triangles, out.normals);
}

void poseAt(const Scene& scene, const SkinnedMesh& mesh, const Animation* animation, float t,
            PosedMesh& out) {
  VS_CHECK(mesh.skin >= 0 && size_t(mesh.skin) < scene.skins.size());
  poseMesh(mesh,
           jointMatrices(scene.skins[size_t(mesh.skin)], globalNodeMatrices(scene, animation, t)),
           out);
}

const Animation* findAnimation(const Scene& scene, const std::string& name) {
  auto lower = [](std::string s) {
    std::transform(s.begin(), s.end(), s.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return s;
  };
  for (const Animation& a : scene.animations)
    if (lower(a.name) == lower(name)) return &a;
  return nullptr;
}

}  // namespace vistream
