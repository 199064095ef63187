// The built-in skinned walker (generate.h: generateWalker): a figure of
// boxes on nine joints with three clips, a test model for avatars and
// self-shadowing that needs no file.
#include <algorithm>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>

#include "common/generate/generate.h"

namespace vistream {
namespace {

enum Joint : uint16_t { kHips, kSpine, kHead, kThighL, kShinL, kThighR, kShinR, kArmL, kArmR };

struct JointSpec {
  const char* name;
  int32_t parent;
  glm::vec3 at;  // global bind position, metres
};

const JointSpec kJoints[] = {
    {"hips", -1, {0.0f, 0.95f, 0.0f}},          {"spine", kHips, {0.0f, 1.05f, 0.0f}},
    {"head", kSpine, {0.0f, 1.55f, 0.0f}},      {"thigh_l", kHips, {-0.11f, 0.92f, 0.0f}},
    {"shin_l", kThighL, {-0.11f, 0.48f, 0.0f}}, {"thigh_r", kHips, {0.11f, 0.92f, 0.0f}},
    {"shin_r", kThighR, {0.11f, 0.48f, 0.0f}},  {"arm_l", kSpine, {-0.25f, 1.45f, 0.0f}},
    {"arm_r", kSpine, {0.25f, 1.45f, 0.0f}},
};

// Skin weights of a vertex at height y of a limb running from joint
// `upper` (above `split`) to `lower`, blended over `blend` metres.
glm::vec4 blendAt(float y, float split, float blend) {
  const float w = std::clamp((y - (split - blend)) / (2.0f * blend), 0.0f, 1.0f);
  return {w, 1.0f - w, 0.0f, 0.0f};
}

class Builder {
 public:
  Builder(Scene& scene, Object& o) : scene_(scene), mesh_(o.mesh) {}

  // A box from lo to hi cut into `segments` slices along y, each vertex
  // skinned by weightsAt(y) over joints (a, b). Closed, outward-wound.
  template <class WeightsAt>
  void box(glm::vec3 lo, glm::vec3 hi, int segments, Joint a, Joint b, WeightsAt&& weightsAt) {
    const uint32_t base = uint32_t(mesh_.positions.size());
    // Rings of 4 corners from bottom to top.
    for (int s = 0; s <= segments; ++s) {
      const float y = lo.y + (hi.y - lo.y) * float(s) / float(segments);
      for (const glm::vec2 c : {glm::vec2(lo.x, lo.z), glm::vec2(hi.x, lo.z), glm::vec2(hi.x, hi.z),
                                glm::vec2(lo.x, hi.z)}) {
        mesh_.positions.emplace_back(c.x, y, c.y);
        mesh_.joints.emplace_back(a, b, 0, 0);
        mesh_.weights.push_back(weightsAt(y));
      }
    }
    auto at = [&](int s, int k) { return base + uint32_t(4 * s + (k & 3)); };
    for (int s = 0; s < segments; ++s)
      for (int k = 0; k < 4; ++k)  // sides, outward
        quad(at(s, k), at(s, k + 1), at(s + 1, k + 1), at(s + 1, k));
    quad(at(0, 0), at(0, 3), at(0, 2), at(0, 1));                              // bottom
    quad(at(segments, 0), at(segments, 1), at(segments, 2), at(segments, 3));  // top
  }

 private:
  // a, b, c, d in clockwise order seen from outside; wound counter-clockwise.
  void quad(uint32_t a, uint32_t b, uint32_t c, uint32_t d) {
    const uint32_t face = scene_.faceCount++;
    mesh_.triangles.emplace_back(a, c, b);
    mesh_.triangles.emplace_back(a, d, c);
    mesh_.faceIds.insert(mesh_.faceIds.end(), {face, face});
    mesh_.materials.insert(mesh_.materials.end(), {0u, 0u});
  }
  Scene& scene_;
  TriangleMesh& mesh_;
};

glm::vec4 rotationX(float degrees) {
  const glm::quat q = glm::angleAxis(glm::radians(degrees), glm::vec3(1, 0, 0));
  return {q.x, q.y, q.z, q.w};
}
glm::vec4 rotationY(float degrees) {
  const glm::quat q = glm::angleAxis(glm::radians(degrees), glm::vec3(0, 1, 0));
  return {q.x, q.y, q.z, q.w};
}

// A clip of `duration` seconds sampled at 16 keys: per joint, a rotation
// angle over the phase (0..1) about X, or about Y for `aboutY` joints.
template <class Angle>
Animation clip(const char* name, float duration, std::initializer_list<Joint> joints, Angle&& angle,
               std::initializer_list<Joint> aboutY = {}) {
  Animation a;
  a.name = name;
  a.duration = duration;
  for (Joint j : joints) {
    AnimationChannel c;
    c.node = j;
    c.path = AnimationChannel::Path::Rotation;
    const bool y = std::find(aboutY.begin(), aboutY.end(), j) != aboutY.end();
    for (int k = 0; k <= 16; ++k) {
      const float phase = float(k) / 16.0f;
      c.times.push_back(duration * phase);
      c.values.push_back(y ? rotationY(angle(j, phase)) : rotationX(angle(j, phase)));
    }
    a.channels.push_back(std::move(c));
  }
  return a;
}

}  // namespace

Scene generateWalker() {
  Scene scene;
  scene.name = "walker";
  scene.sources = {"walker"};
  scene.materials.push_back(Material::diffuseColour("cloth", {0.25f, 0.35f, 0.7f}));
  for (const JointSpec& j : kJoints) {
    Node n;
    n.name = j.name;
    n.parent = j.parent;
    n.translation = j.parent < 0 ? j.at : j.at - kJoints[j.parent].at;
    scene.nodes.push_back(n);
  }
  Skin skin;
  skin.name = "walker";
  for (int32_t j = 0; j < int32_t(std::size(kJoints)); ++j) {
    skin.joints.push_back(j);
    skin.inverseBindMatrices.push_back(glm::translate(glm::mat4(1.0f), -kJoints[j].at));
  }
  scene.skins.push_back(skin);

  Object o;
  o.name = "walker";
  o.dynamic = true;
  o.skin = 0;
  Builder b(scene, o);
  // Torso: hips below 1.1 m, spine above, blended over 10 cm.
  b.box({-0.18f, 0.88f, -0.1f}, {0.18f, 1.5f, 0.1f}, 6, kSpine, kHips,
        [](float y) { return blendAt(y, 1.1f, 0.05f); });
  b.box({-0.09f, 1.52f, -0.1f}, {0.09f, 1.75f, 0.1f}, 1, kHead, kHead,
        [](float) { return glm::vec4(1, 0, 0, 0); });
  for (const float side : {-1.0f, 1.0f}) {
    const Joint thigh = side < 0 ? kThighL : kThighR, shin = side < 0 ? kShinL : kShinR;
    const Joint arm = side < 0 ? kArmL : kArmR;
    const float x = 0.11f * side;
    b.box({x - 0.06f, 0.0f, -0.07f}, {x + 0.06f, 0.88f, 0.07f}, 8, thigh, shin,
          [](float y) { return blendAt(y, 0.48f, 0.06f); });
    const float ax = 0.25f * side;
    b.box({ax - 0.05f, 0.85f, -0.05f}, {ax + 0.05f, 1.47f, 0.05f}, 4, arm, arm,
          [](float) { return glm::vec4(1, 0, 0, 0); });
  }
  scene.objects.push_back(std::move(o));

  constexpr float kTwoPi = 6.2831853f;
  // Legs swing opposite each other, arms against their legs; the shin
  // bends back (negative about X) while its leg swings forward.
  auto gait = [](float swing, float knee, float arms, float lean) {
    return [=](Joint j, float phase) {
      const float s = std::sin(kTwoPi * phase);
      switch (j) {
        case kThighL:
          return -swing * s;
        case kThighR:
          return swing * s;
        case kShinL:
          return knee * std::max(0.0f, s);
        case kShinR:
          return knee * std::max(0.0f, -s);
        case kArmL:
          return arms * s;
        case kArmR:
          return -arms * s;
        case kSpine:
          return -lean;
        default:
          return 0.0f;
      }
    };
  };
  const std::initializer_list<Joint> moving = {kThighL, kThighR, kShinL, kShinR,
                                               kArmL,   kArmR,   kSpine};
  scene.animations.push_back(clip("Survey", 3.0f, {kHead, kSpine},
                                  [](Joint j, float phase) {
                                    const float s = std::sin(kTwoPi * phase);
                                    return j == kHead ? 40.0f * s : 8.0f * s;
                                  },
                                  {kHead, kSpine}));
  scene.animations.push_back(clip("Walk", 1.0f, moving, gait(25.0f, 35.0f, 20.0f, 3.0f)));
  scene.animations.push_back(clip("Run", 0.6f, moving, gait(45.0f, 70.0f, 40.0f, 12.0f)));
  finalizeScene(scene);
  return scene;
}

}  // namespace vistream
