#include "client/avatar/avatar_view.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>

#include "common/core/check.h"
#include "common/core/timer.h"

namespace vistream {
namespace {

// The model's +Z (glTF's front) turned to the view direction of `yawDeg`.
float modelTurnDeg(float yawDeg) {
  return yawDeg + 180.0f;
}

// That turn as a rotation about +Y (model frame to world frame).
glm::mat3 modelTurn(float yawDeg) {
  return glm::mat3(
      glm::rotate(glm::mat4(1.0f), glm::radians(modelTurnDeg(yawDeg)), glm::vec3(0, 1, 0)));
}

// Whether a sphere reaches into the camera's view frustum (its side planes
// and the half-space in front of the eye).
bool sphereInFrustum(const Camera& camera, const glm::vec3& centre, float radius) {
  const glm::vec3 d = centre - camera.eye;
  const float z = glm::dot(d, camera.forward());
  if (z < -radius) return false;
  const float x = std::abs(glm::dot(d, camera.right())), y = std::abs(glm::dot(d, camera.up()));
  const float h = camera.halfHfov(), v = glm::radians(0.5f * camera.vfovDeg);
  // Distance from the point to each side plane, along its normal.
  const float outX = x * std::cos(h) - z * std::sin(h), outY = y * std::cos(v) - z * std::sin(v);
  return outX <= radius && outY <= radius;
}

}  // namespace

void appendAvatar(const AvatarModel& model, const ShadedAvatar& shaded, const glm::vec3& feet,
                  float yawDeg, uint32_t object, RenderGeometry& out) {
  const glm::mat3 turn = modelTurn(yawDeg);
  const auto& triangles = model.triangles();
  VS_CHECK_EQ(shaded.corners.size(), 3 * triangles.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    glm::vec3 p[3];
    for (int k = 0; k < 3; ++k) {
      p[k] = feet + turn * shaded.positions[triangles[t][k]];
      out.triangles.positions.push_back(p[k]);
      out.bounds.extend(p[k]);
    }
    out.triangles.faceIds.push_back(t < model.faceIds().size() ? model.faceIds()[t] : uint32_t(t));
    out.triangles.objectIds.push_back(object);
    out.triangles.degenerate.push_back(isDegenerateTriangle(p[0], p[1], p[2]) ? 1 : 0);
    out.lighting.append(1, shaded.corners.data() + 3 * t, 3);
  }
}

AvatarView::AvatarView(std::shared_ptr<const AvatarModel> model, const AvatarLight& light,
                       Haze haze, const RayQuery* rays, const AvatarShaderOptions& options)
    : light_(light), haze_(haze), rays_(rays), options_(options) {
  if (model) setModel(0, std::move(model));
}

void AvatarView::setModel(uint16_t index, std::shared_ptr<const AvatarModel> model) {
  if (shaders_.size() <= index) shaders_.resize(size_t(index) + 1);
  shaders_[index] = model ? std::make_unique<AvatarShader>(std::move(model), options_) : nullptr;
}

glm::vec3 AvatarView::feetOf(const AvatarState& s) const {
  glm::vec3 feet = s.eye - glm::vec3(0.0f, kEyeHeight, 0.0f);
  if (rays_) {
    const Hit floor = rays_->firstHit(Ray{s.eye, glm::vec3(0, -1, 0), 0.0f, kEyeHeight + 1.3f});
    if (floor.triangle != kNoHit) feet.y = s.eye.y - floor.t;
  }
  return feet;
}

AvatarFrame AvatarView::build(const Camera& camera, float nearDistance,
                              const std::vector<AvatarState>& states, RenderGeometry& out) {
  Stopwatch clock;
  out = RenderGeometry{};
  out.haze = haze_;
  AvatarFrame f;
  for (size_t i = 0; i < states.size(); ++i) {
    const AvatarState& s = states[i];
    if (!std::isfinite(s.eye.x) || !std::isfinite(s.eye.y) || !std::isfinite(s.eye.z)) continue;
    if (!hasModel(s.model)) {
      ++f.waiting;
      continue;
    }
    AvatarShader& shader = *shaders_[s.model];
    const AvatarModel& model = shader.model();
    const glm::vec3 feet = feetOf(s);
    const glm::vec3 centre = feet + glm::vec3(0.0f, 0.5f * model.height(), 0.0f);
    const float radius = model.boundingRadius();
    if (!sphereInFrustum(camera, centre, radius)) {
      ++f.outside;
      continue;
    }
    if (glm::length(centre - camera.eye) - radius > nearDistance) {
      ++f.beyond;
      continue;
    }
    ++f.inView;
    float sunVisible = 1.0f;
    if (rays_ && glm::length(light_.sunDirection) > 0.0f)
      sunVisible = rays_->occluded(Ray{centre, light_.sunDirection, 0.0f,
                                       std::numeric_limits<float>::infinity()})
                       ? 0.0f
                       : 1.0f;
    const AvatarShader::Stats before = shader.stats();
    // The viewer in the model's frame (appendAvatar's placement undone), for
    // the glossy term and front-facing shading.
    const glm::vec3 eye = glm::transpose(modelTurn(s.yawDeg)) * (camera.eye - feet);
    shader.shade(gaitForSpeed(s.speed), s.phase, light_.turned(modelTurnDeg(s.yawDeg)), sunVisible,
                 scratch_, &eye);
    f.posesShaded += shader.stats().posesShaded - before.posesShaded;
    f.posesReused += shader.stats().posesReused - before.posesReused;
    f.verticesShaded += shader.stats().verticesShaded - before.verticesShaded;
    appendAvatar(model, scratch_, feet, s.yawDeg, uint32_t(i), out);
  }
  if (states.empty()) {
    f.why = "no dynamic objects";
  } else {
    f.why = fmt::format("{} avatar{} in view", f.inView, f.inView == 1 ? "" : "s");
    if (f.inView && options_.glossExponent > 0.0f)
      f.why += fmt::format(" (glossy, Phong {:g})", options_.glossExponent);
    if (f.beyond) f.why += fmt::format(", {} beyond d", f.beyond);
    if (f.outside) f.why += fmt::format(", {} outside the view", f.outside);
    if (f.waiting) f.why += fmt::format(", {} waiting for their model", f.waiting);
  }
  f.ms = clock.ms();
  return f;
}

}  // namespace vistream
