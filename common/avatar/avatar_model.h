// Avatars: a skinned glTF model made ready to stand for a user in a scene,
// and its self-shadowed colours under the scene's light.
//
// An AvatarModel is a skinned model (skinning.h) in metres: scaled so its
// rest pose is `height` tall, its feet on y = 0 and its footprint centred on
// the origin, facing +Z (glTF's front). A user's avatar stands at its feet
// position and turns with the user's yaw: the model's +Z becomes the view
// direction (yaw 0 looks along -Z, so the model turns by yaw + 180 degrees).
//
// Gait follows speed: standing (below kStandingSpeed) plays the model's
// idle clip ("Survey" on the Fox), walking its "Walk" clip, running (from
// kRunningSpeed) its "Run" clip; a model without a clip of that name plays
// its first clip, and a model without clips stands in its rest pose.
//
// Shading (AvatarShader) follows Kautz, Lehtinen and Aila (2004): per
// vertex a diffuse SH transfer vector with self-shadowing (self_shadow.h),
// dotted with the light. The light is the static scene's, in the same
// units as its baked colours (common/light/lighting.h): the environment's
// radiance times skyExposure plus the sun projected into the same 25
// coefficients, so an avatar's open, up-facing white surface gets what a
// static one gets, and parts it shadows itself get less. Corner colours are
// the vertex's light times the albedo of its material and texture around the
// corner's texture coordinate, encoded as the baked colours are (gamma 2.2).
//
// Coefficient reuse: a pose depends on (clip, clip time) only, so the shader
// samples clip time at `poseRate` poses a second and keeps each sampled
// pose's positions, normals and transfer vectors in model space; turning an
// avatar rotates the light, not the transfer vectors (SH rotation). Many
// avatars playing the same clip share the work. Each clip's blockers are
// cut to a per-vertex PVS from poses of the clip when it is first played
// (Kautz et al. section 3.2; for the Fox about 0.1 s, and 4 times fewer
// blockers a vertex).
//
// Thread safety: an AvatarModel is immutable. An AvatarShader's shade() may
// not run concurrently with itself (its pose cache); the self-shadow loop
// inside runs in parallel (TBB).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <glm/glm.hpp>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "common/avatar/self_shadow.h"
#include "common/avatar/skinning.h"
#include "common/light/environment_light.h"
#include "common/light/lighting.h"
#include "common/scene/scene.h"

namespace vistream {

enum class Gait : uint8_t { Stand, Walk, Run };
const char* gaitName(Gait g);
inline constexpr float kStandingSpeed = 0.2f;  // m/s: slower is standing
inline constexpr float kRunningSpeed = 2.5f;   // m/s: faster is running
Gait gaitForSpeed(float metresPerSecond);

class AvatarModel {
 public:
  // The first skinned object of `scene` (InputError if none, naming
  // `name`). heightM > 0.
  static AvatarModel fromScene(Scene scene, const std::string& name, float heightM);
  // Loads a skinned glTF file (loadScene; InputError naming the file).
  static AvatarModel load(const std::filesystem::path& file, float heightM);

  const std::string& name() const { return name_; }
  float height() const { return height_; }
  // Welded vertices (one per position and skin): what is posed and shaded.
  size_t vertexCount() const { return welded_.positions.size(); }
  size_t triangleCount() const { return welded_.triangles.size(); }
  const std::vector<glm::uvec3>& triangles() const { return welded_.triangles; }
  // The welded vertices in the bind pose.
  const std::vector<glm::vec3>& restPositions() const { return welded_.positions; }
  // Per triangle corner (3t + k): linear albedo.
  const std::vector<glm::vec3>& cornerAlbedo() const { return cornerAlbedo_; }
  // Face IDs of the model's source file, per triangle.
  const std::vector<uint32_t>& faceIds() const { return source_.faceIds; }
  // The clip played for a gait (null: the rest pose), and its length in
  // seconds (0 without a clip).
  const Animation* clip(Gait g) const { return clips_[size_t(g)]; }
  float clipDuration(Gait g) const;
  // Radius of a sphere around (0, height / 2, 0) holding every pose of
  // every clip (sampled), metres: for culling against the view.
  float boundingRadius() const { return boundingRadius_; }
  // Warnings met while loading (missing textures).
  const std::vector<std::string>& warnings() const { return warnings_; }

  // Positions (metres, model frame as above) and unit normals of the welded
  // vertices at clip time t of gait g's clip.
  void pose(Gait g, float t, PosedMesh& out) const;

 private:
  std::string name_;
  float height_ = 1.0f;
  std::shared_ptr<const Scene> scene_;
  SkinnedMesh source_, welded_;
  std::vector<glm::vec3> cornerAlbedo_;
  std::array<const Animation*, 3> clips_{};
  glm::mat4 toMetres_{1.0f};
  float boundingRadius_ = 1.0f;
  std::vector<std::string> warnings_;
};

// The light an avatar is shaded with: 25 RGB coefficients (orders 0..4) in
// the units of the static scene's baked colours.
struct AvatarLight {
  std::array<glm::vec3, 25> sky{};  // the environment's radiance times skyExposure
  std::array<float, 25> sun{};      // sunIntensity times the sun as a directional light (white)
  glm::vec3 sunDirection{0.0f};     // towards the sun, world frame (turned() keeps it); 0: no sun
  static AvatarLight of(const EnvironmentLight& environment, const Environment& scene,
                        const LightingOptions& options = {});
  // The same light seen from a model turned by `yawDeg` about +Y (as
  // AvatarPlacement turns it): rotated the other way.
  AvatarLight turned(float yawDeg) const;
  // Sum of t_i (sky_i + sunVisible sun_i) per channel for a transfer vector
  // of 25 terms, clamped at 0.
  glm::vec3 apply(const float* transfer, float sunVisible = 1.0f) const;
};

struct AvatarShaderOptions {
  SelfShadowOptions shadows;
  float poseRate = 30.0f;  // sampled poses a second of clip time; 0: every pose exactly
  // The cache of sampled poses is emptied when it would pass either bound
  // (with gloss each pose keeps its masks: 128 bytes a vertex at 32 x 32).
  size_t maxCachedPoses = 1024;
  size_t maxCacheBytes = size_t(256) << 20;
  // Per clip, a per-vertex PVS (self_shadow.h: potentiallyVisibleBlockers)
  // from this many poses of the clip, built when the clip is first played;
  // 0 (or a model with more than kMaxPvsEntries vertex-triangle pairs):
  // every triangle blocks every vertex.
  int pvsPoses = 16;
  static constexpr size_t kMaxPvsEntries = 16u << 20;
  // Glossy reflection (the paper's glossy BRDF): a normalized Phong lobe of
  // this exponent about the viewer's reflected direction, self-shadowed
  // through the same visibility masks, added with weight `specular`. It is
  // view-dependent, so it is integrated per frame and viewer from the masks
  // kept with each sampled pose, per mask pixel: with glossInBlocks, in the
  // paper's 4 x 4 blocks instead, 5 times faster but 4 times the error on the
  // Fox (10.5% against 2.6% at exponent 16, `vistream-client-bench
  // --shadows`), and blocks lose a narrow lobe altogether (34% off at 256).
  // 0: off (diffuse only, nothing kept).
  float glossExponent = 0.0f;
  bool glossInBlocks = false;
  float specular = 0.25f;
  // The paper's saving: given a viewer, shade only the vertices of the
  // triangles that face it, and the rest of a sampled pose when another
  // viewer needs them (each vertex is shaded once per pose whoever asks).
  // Used only on models whose every part is closed, manifold and wound
  // outward at rest (Solids' reading), where a triangle facing away is
  // hidden by the model itself; other models are shaded whole.
  bool frontFacingOnly = true;
};

struct ShadedAvatar {
  std::vector<glm::vec3> positions;  // per welded vertex, model frame (metres)
  std::vector<glm::u8vec3> corners;  // per triangle corner: encoded colour
};

class AvatarShader {
 public:
  AvatarShader(std::shared_ptr<const AvatarModel> model, const AvatarShaderOptions& options = {});
  const AvatarModel& model() const { return *model_; }
  const AvatarShaderOptions& options() const { return options_; }

  // The model in gait g at clip time t, lit by `light` (already turned to
  // the model's frame), its sun dimmed by `sunVisible` in [0, 1] (the static
  // scene's shadow). `eye` is the viewer in the model's frame (metres): with
  // it, glossExponent > 0 adds the glossy term for that viewer, and with
  // frontFacingOnly only what the viewer can see need be shaded (the corners
  // of triangles facing away from it may then be black).
  void shade(Gait g, float t, const AvatarLight& light, float sunVisible, ShadedAvatar& out,
             const glm::vec3* eye = nullptr);
  // Whether front-facing shading applies to this model (closed outward).
  bool shadesFrontFacingOnly() const { return frontFacingOnly_; }

  struct Stats {
    uint64_t posesShaded = 0;     // self-shadow loops run
    uint64_t posesReused = 0;     // served from the cache with nothing left to shade
    uint64_t verticesShaded = 0;  // by those loops
    double shadowMs = 0.0;        // in the self-shadow loops
    double pvsMs = 0.0;           // building per-clip PVSs
    double glossyMs = 0.0;        // integrating the glossy term
  };
  const Stats& stats() const { return stats_; }

 private:
  struct Sampled {
    PosedMesh pose;
    std::vector<float> transfer;  // zeros where not shaded yet
    std::vector<uint64_t> masks;  // with gloss: maskWords() per vertex
    std::vector<uint8_t> shaded;  // per vertex
  };
  const Sampled& sampled(Gait g, float t, const glm::vec3* eye);
  // Shades the vertices of `s` that the viewer at `eye` (null: any viewer)
  // needs and that are not shaded yet; false if there were none.
  bool shadeMissing(Gait g, Sampled& s, const glm::vec3* eye);
  size_t poseBytes() const;                // what one sampled pose holds
  const VertexBlockers* blockers(Gait g);  // null: every triangle
  std::shared_ptr<const AvatarModel> model_;
  std::array<std::unique_ptr<VertexBlockers>, 3> pvs_;  // per gait, once built
  TriangleGroups groups_;                               // of the model's triangles, for culling
  std::array<bool, 3> pvsTried_{};
  AvatarShaderOptions options_;
  bool frontFacingOnly_ = false;  // options_.frontFacingOnly on a closed outward model
  SelfShadowing shadowing_;
  TransferIntegrator glossy_;  // per pixel, or 4 x 4 blocks with glossInBlocks
  std::map<std::pair<int, int64_t>, Sampled> cache_;
  size_t cacheBytes_ = 0;  // of cache_'s poses, as poseBytes() counts them
  Sampled exact_;
  Stats stats_;
};

}  // namespace vistream
