#include "common/avatar/avatar_model.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <numbers>

#include "common/core/check.h"
#include "common/core/error.h"
#include "common/core/timer.h"
#include "common/light/spherical_harmonics.h"
#include "common/light/texture.h"
#include "common/scene/scene_loader.h"
#include "common/world/solids.h"

namespace vistream {
namespace {

constexpr int kOrders = 5;
constexpr int kTerms = shTerms(kOrders);

// The clip a gait plays: the first whose name holds one of `names`, else the
// model's first clip.
const Animation* clipFor(const Scene& scene, std::initializer_list<const char*> names) {
  for (const char* n : names)
    if (const Animation* a = findAnimation(scene, n)) return a;
  return scene.animations.empty() ? nullptr : &scene.animations.front();
}

}  // namespace

const char* gaitName(Gait g) {
  switch (g) {
    case Gait::Stand:
      return "stand";
    case Gait::Walk:
      return "walk";
    case Gait::Run:
      return "run";
  }
  return "?";
}

Gait gaitForSpeed(float metresPerSecond) {
  if (!(metresPerSecond >= kStandingSpeed)) return Gait::Stand;  // NaN too
  return metresPerSecond >= kRunningSpeed ? Gait::Run : Gait::Walk;
}

AvatarModel AvatarModel::fromScene(Scene scene, const std::string& name, float heightM) {
  if (!(heightM > 0.0f) || !std::isfinite(heightM))
    throwInputError("avatar height {}: must be a positive number of metres", heightM);
  AvatarModel m;
  m.name_ = name;
  m.height_ = heightM;
  m.source_ = SkinnedMesh::firstOf(scene);  // InputError if none
  m.welded_ = m.source_.subdivided(0);      // same triangle order as the source
  m.clips_[size_t(Gait::Stand)] = clipFor(scene, {"survey", "idle", "stand"});
  m.clips_[size_t(Gait::Walk)] = clipFor(scene, {"walk"});
  m.clips_[size_t(Gait::Run)] = clipFor(scene, {"run", "walk"});

  // Albedo per corner: the material's colour times its texture's mean over
  // a box half the triangle's texture footprint around the corner.
  const auto textures = loadMaterialTextures(scene, m.warnings_);
  const size_t triangles = m.source_.triangles.size();
  m.cornerAlbedo_.resize(3 * triangles);
  for (size_t t = 0; t < triangles; ++t) {
    const uint32_t mat = t < m.source_.materials.size() ? m.source_.materials[t] : 0u;
    const Material* material = mat < scene.materials.size() ? &scene.materials[mat] : nullptr;
    const glm::vec3 diffuse = material ? material->diffuse : glm::vec3(0.8f);
    const Texture* texture = mat < textures.size() && textures[mat] && !m.source_.texcoords.empty()
                                 ? &*textures[mat]
                                 : nullptr;
    glm::vec2 uv[3];
    for (int k = 0; k < 3; ++k)
      uv[k] = texture ? m.source_.texcoords[m.source_.triangles[t][k]] : glm::vec2(0.0f);
    const glm::vec2 half =
        0.25f * (glm::max(uv[0], glm::max(uv[1], uv[2])) - glm::min(uv[0], glm::min(uv[1], uv[2])));
    for (int k = 0; k < 3; ++k)
      m.cornerAlbedo_[3 * t + size_t(k)] =
          texture ? diffuse * texture->mean(uv[k] - half, uv[k] + half) : diffuse;
  }

  // Metres: the rest pose's bounds give the scale and the feet.
  PosedMesh rest;
  poseAt(scene, m.welded_, nullptr, 0.0f, rest);
  Box3f bounds;
  for (const glm::vec3& p : rest.positions) bounds.extend(p);
  const float tall = bounds.empty() ? 0.0f : bounds.hi.y - bounds.lo.y;
  if (!(tall > 0.0f) || !std::isfinite(tall))
    throwInputError("{}: the avatar's rest pose has no height", name);
  const float scale = heightM / tall;
  const glm::vec3 feet(0.5f * (bounds.lo.x + bounds.hi.x), bounds.lo.y,
                       0.5f * (bounds.lo.z + bounds.hi.z));
  m.toMetres_ =
      glm::scale(glm::mat4(1.0f), glm::vec3(scale)) * glm::translate(glm::mat4(1.0f), -feet);
  m.scene_ = std::make_shared<const Scene>(std::move(scene));

  // Bounding sphere over sampled poses of every clip.
  const glm::vec3 centre(0.0f, 0.5f * heightM, 0.0f);
  float radius = 0.0f;
  PosedMesh p;
  for (Gait g : {Gait::Stand, Gait::Walk, Gait::Run}) {
    const float duration = m.clipDuration(g);
    for (int k = 0; k < 16; ++k) {
      m.pose(g, duration * float(k) / 16.0f, p);
      for (const glm::vec3& x : p.positions) radius = std::max(radius, glm::length(x - centre));
    }
  }
  m.boundingRadius_ = 1.1f * radius;  // the poses between samples
  return m;
}

AvatarModel AvatarModel::load(const std::filesystem::path& file, float heightM) {
  Scene scene = loadScene(file);
  if (scene.skins.empty())
    throwInputError("{}: not an avatar model: no skin (a glTF mesh with JOINTS_0 and WEIGHTS_0)",
                    file.string());
  return fromScene(std::move(scene), file.filename().string(), heightM);
}

float AvatarModel::clipDuration(Gait g) const {
  const Animation* a = clip(g);
  return a ? a->duration : 0.0f;
}

void AvatarModel::pose(Gait g, float t, PosedMesh& out) const {
  poseAt(*scene_, welded_, clip(g), t, out);
  for (glm::vec3& p : out.positions) p = glm::vec3(toMetres_ * glm::vec4(p, 1.0f));
  // A uniform scale and a translation leave normals as they are.
}

AvatarLight AvatarLight::of(const EnvironmentLight& environment, const Environment& scene,
                            const LightingOptions& options) {
  AvatarLight l;
  const float sky = skyExposure(environment, options);
  for (int i = 0; i < kTerms; ++i) l.sky[size_t(i)] = environment.radiance()[size_t(i)] * sky;
  const float sunIntensity = options.sunIntensity.value_or(scene.sunIntensity);
  const glm::vec3 sun = options.sunDirection.value_or(scene.sunDirection);
  if (sunIntensity > 0.0f && glm::length(sun) > 0.0f) {
    float y[kTerms];
    shEvaluate(glm::normalize(sun), kOrders, y);
    for (int i = 0; i < kTerms; ++i) l.sun[size_t(i)] = sunIntensity * y[i];
    l.sunDirection = glm::normalize(sun);
  }
  return l;
}

AvatarLight AvatarLight::turned(float yawDeg) const {
  // The model turned by R: light arriving from world direction w arrives
  // from R^-1 w in its frame, so its coefficients rotate by R^-1.
  const glm::mat3 inverse =
      glm::mat3(glm::rotate(glm::mat4(1.0f), glm::radians(-yawDeg), glm::vec3(0, 1, 0)));
  const ShRotation rotation(inverse, kOrders);
  AvatarLight out;
  out.sunDirection = sunDirection;
  for (int c = 0; c < 3; ++c) {
    float in[kTerms], rotated[kTerms];
    for (int i = 0; i < kTerms; ++i) in[i] = sky[size_t(i)][c];
    rotation.apply(in, rotated);
    for (int i = 0; i < kTerms; ++i) out.sky[size_t(i)][c] = rotated[i];
  }
  rotation.apply(sun.data(), out.sun.data());
  return out;
}

glm::vec3 AvatarLight::apply(const float* transfer, float sunVisible) const {
  glm::vec3 c(0.0f);
  float s = 0.0f;
  for (int i = 0; i < kTerms; ++i) {
    c += sky[size_t(i)] * transfer[i];
    s += sun[size_t(i)] * transfer[i];
  }
  return glm::max(c + glm::vec3(std::max(0.0f, sunVisible * s)), glm::vec3(0.0f));
}

namespace {

// Whether every component of the mesh at rest is closed, manifold and wound
// outward (Solids' reading, common/world/solids.h).
bool closedOutward(const std::vector<glm::vec3>& positions,
                   const std::vector<glm::uvec3>& triangles) {
  const Solids solids =
      Solids::build(flattenMesh(positions, triangles), SolidsOptions{.weldTolerance = 0.0});
  if (solids.components().empty()) return false;
  for (const SolidComponent& c : solids.components())
    if (c.kind != SolidClass::ClosedOutward) return false;
  return true;
}

}  // namespace

AvatarShader::AvatarShader(std::shared_ptr<const AvatarModel> model,
                           const AvatarShaderOptions& options)
    : model_(std::move(model)),
      options_(options),
      shadowing_(options.shadows),
      glossy_(options.shadows.maskSide, {kOrders, options.glossInBlocks}) {
  VS_CHECK(model_ != nullptr);
  groups_ = TriangleGroups::build(model_->triangles(), model_->restPositions());
  frontFacingOnly_ =
      options_.frontFacingOnly && closedOutward(model_->restPositions(), model_->triangles());
  VS_CHECK_EQ(shadowing_.terms(), kTerms);
}

const VertexBlockers* AvatarShader::blockers(Gait g) {
  const size_t i = size_t(g);
  if (pvsTried_[i]) return pvs_[i].get();
  pvsTried_[i] = true;
  const size_t entries = model_->vertexCount() * model_->triangleCount();
  if (options_.pvsPoses <= 0 || entries > AvatarShaderOptions::kMaxPvsEntries) return nullptr;
  Stopwatch clock;
  const float duration = model_->clipDuration(g);
  std::vector<PosedMesh> poses(duration > 0.0f ? size_t(options_.pvsPoses) : 1);
  for (size_t k = 0; k < poses.size(); ++k)
    model_->pose(g, duration * float(k) / float(poses.size()), poses[k]);
  VertexBlockers every = VertexBlockers::everyTriangle(model_->triangles(), model_->vertexCount());
  every.groups = groups_;
  pvs_[i] =
      std::make_unique<VertexBlockers>(potentiallyVisibleBlockers(every, poses, options_.shadows));
  stats_.pvsMs += clock.ms();
  return pvs_[i].get();
}

size_t AvatarShader::poseBytes() const {
  const size_t perVertex =
      2 * sizeof(glm::vec3) + kTerms * sizeof(float) +
      (options_.glossExponent > 0.0f ? size_t(shadowing_.maskWords()) * sizeof(uint64_t) : 0);
  return model_->vertexCount() * perVertex;
}

const AvatarShader::Sampled& AvatarShader::sampled(Gait g, float t, const glm::vec3* eye) {
  const float duration = model_->clipDuration(g);
  float clipTime = duration > 0.0f ? std::fmod(t, duration) : 0.0f;
  if (clipTime < 0.0f) clipTime += duration;
  Sampled* slot = &exact_;
  bool fresh = true;
  if (options_.poseRate > 0.0f) {
    const int64_t k = int64_t(std::floor(clipTime * options_.poseRate));
    clipTime = float(k) / options_.poseRate;
    const auto key = std::make_pair(int(g), k);
    if (auto it = cache_.find(key); it != cache_.end()) {
      slot = &it->second;
      fresh = false;
    } else {
      if (cache_.size() >= options_.maxCachedPoses ||
          cacheBytes_ + poseBytes() > options_.maxCacheBytes) {
        cache_.clear();
        cacheBytes_ = 0;
      }
      slot = &cache_[key];
      cacheBytes_ += poseBytes();
    }
  }
  if (fresh) {
    model_->pose(g, clipTime, slot->pose);
    const size_t vertices = slot->pose.positions.size();
    slot->transfer.assign(vertices * size_t(kTerms), 0.0f);
    slot->shaded.assign(vertices, 0);
    slot->masks.assign(
        options_.glossExponent > 0.0f ? vertices * size_t(shadowing_.maskWords()) : 0, 0);
  }
  if (!shadeMissing(g, *slot, eye) && !fresh) ++stats_.posesReused;
  return *slot;
}

bool AvatarShader::shadeMissing(Gait g, Sampled& s, const glm::vec3* eye) {
  const size_t vertices = s.pose.positions.size();
  std::vector<uint8_t> needed = eye && frontFacingOnly_
                                    ? verticesFacing(s.pose.positions, model_->triangles(), *eye)
                                    : std::vector<uint8_t>(vertices, 1);
  size_t count = 0;
  for (size_t v = 0; v < vertices; ++v) {
    needed[v] = needed[v] && !s.shaded[v];
    count += needed[v];
  }
  if (count == 0) return false;
  const auto start = std::chrono::steady_clock::now();
  const bool gloss = options_.glossExponent > 0.0f;
  // Straight into the pose: `only` leaves the vertices shaded before as they are.
  const ShadeExtras extras{.only = &needed, .masks = gloss ? &s.masks : nullptr};
  if (const VertexBlockers* pvs = blockers(g)) {
    shadowing_.diffuse(s.pose.positions, s.pose.normals, *pvs, s.transfer, extras);
  } else {
    ShadeExtras withGroups = extras;
    withGroups.groups = &groups_;
    shadowing_.diffuse(s.pose.positions, s.pose.normals, model_->triangles(), s.transfer,
                       withGroups);
  }
  for (size_t v = 0; v < vertices; ++v) s.shaded[v] |= needed[v];
  stats_.shadowMs +=
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  ++stats_.posesShaded;
  stats_.verticesShaded += count;
  return true;
}

void AvatarShader::shade(Gait g, float t, const AvatarLight& light, float sunVisible,
                         ShadedAvatar& out, const glm::vec3* eye) {
  const Sampled& s = sampled(g, t, eye);
  out.positions = s.pose.positions;
  const size_t vertices = s.pose.positions.size();
  std::vector<glm::vec3> radiance(vertices);
  for (size_t v = 0; v < vertices; ++v)
    radiance[v] = light.apply(s.transfer.data() + v * size_t(kTerms), sunVisible);
  std::vector<glm::vec3> highlight;  // untinted (a dielectric's highlight is white)
  if (eye && options_.glossExponent > 0.0f && !s.masks.empty()) {
    // Glossy: the lobe about the eye's reflection in each vertex's normal,
    // through the vertex's own mask. The diffuse radiance is in the units
    // the albedo multiplies (pi times a Lambertian BRDF's), so pi ks brings
    // the lobe's radiance to the same scale.
    highlight.assign(vertices, glm::vec3(0.0f));
    const auto start = std::chrono::steady_clock::now();
    const size_t words = size_t(shadowing_.maskWords());
    VisibilityMask mask(options_.shadows.maskSide);
    float glossy[kTerms];
    for (size_t v = 0; v < vertices; ++v) {
      const glm::vec3 n = s.pose.normals[v];
      const glm::vec3 toEye = glm::normalize(*eye - s.pose.positions[v]);
      const float facing = glm::dot(n, toEye);
      if (!(facing > 0.0f) || !s.shaded[v]) continue;
      std::copy_n(s.masks.data() + v * words, words, mask.data());
      glossy_.glossy(mask, TangentFrame::around(n), 2.0f * facing * n - toEye,
                     options_.glossExponent, glossy);
      highlight[v] =
          std::numbers::pi_v<float> * options_.specular * light.apply(glossy, sunVisible);
    }
    stats_.glossyMs +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  }
  const auto& triangles = model_->triangles();
  out.corners.resize(3 * triangles.size());
  for (size_t t3 = 0; t3 < triangles.size(); ++t3)
    for (int k = 0; k < 3; ++k) {
      const size_t c = 3 * t3 + size_t(k);
      const uint32_t v = triangles[t3][k];
      glm::vec3 colour = model_->cornerAlbedo()[c] * radiance[v];
      if (!highlight.empty()) colour += highlight[v];
      out.corners[c] = encodeColour(colour);
    }
}

}  // namespace vistream
