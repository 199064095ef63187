// Other users as animated, self-shadowed avatars in a client's frame.
//
// Each frame the client knows where the other users are (AvatarState: from
// the server's Avatar messages, or from a LocalCrowd without a server). An
// AvatarView decides which of them to draw and builds their triangles as
// dynamic geometry (a RenderGeometry whose corners carry the avatars'
// colours, hazed like the static scene) that both renderers draw over the
// frame with a depth test: OpenGL (GlRenderer::uploadDynamic) and the
// software pipeline (FrameRenderer::drawDynamic).
//
// Simulate only what the frame calls for: the self-shadow loop runs only
// for avatars in view, that is inside the view frustum (their bounding
// sphere) and within the near-field distance d (the far field is ray cast
// from static geometry only, so an avatar beyond d is not drawn).
// AvatarFrame::why says what ran: "2 avatars in view, 1 beyond d, 3 outside
// the view" or "no dynamic objects".
//
// Placement: an AvatarState's position is the user's eye (as in a Pose and
// path files); the feet stand on the first floor a ray finds within 3 m
// below it (when the view has the static scene's rays), else kEyeHeight
// below it. The model turns with the user's yaw (avatar_model.h).
//
// Thread safety: one AvatarView per client frame loop.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "client/render/camera.h"
#include "client/render/render_geometry.h"
#include "common/avatar/avatar_model.h"
#include "common/raycast/ray_query.h"

namespace vistream {

inline constexpr float kEyeHeight = 1.7f;  // metres from the feet to a user's eye

struct AvatarState {
  uint32_t id = 0;
  glm::vec3 eye{0.0f};  // local frame
  float yawDeg = 0.0f;
  float speed = 0.0f;  // m/s over the ground
  float phase = 0.0f;  // seconds into the gait's clip
  uint16_t model = 0;  // which of the view's models draws the user
};

struct AvatarFrame {
  size_t inView = 0, beyond = 0, outside = 0;
  size_t waiting = 0;                       // users whose model has not arrived (connected clients)
  size_t posesShaded = 0, posesReused = 0;  // this frame
  size_t verticesShaded = 0;                // this frame (front-facing ones, on closed models)
  double ms = 0.0;                          // selecting, posing, shading and building
  std::string why;
};

class AvatarView {
 public:
  // `rays` (the static scene's, may be null) places feet on floors and
  // tells whether the sun reaches an avatar; it must outlive the view.
  AvatarView(std::shared_ptr<const AvatarModel> model, const AvatarLight& light, Haze haze,
             const RayQuery* rays, const AvatarShaderOptions& options = {});
  // Sets (or replaces) the model AvatarState::model `index` names; users of
  // a model not set yet are counted as waiting and not drawn.
  void setModel(uint16_t index, std::shared_ptr<const AvatarModel> model);
  bool hasModel(uint16_t index) const { return index < shaders_.size() && shaders_[index]; }
  // The static scene's rays, when the renderer holding them was rebuilt.
  void setRays(const RayQuery* rays) { rays_ = rays; }

  // The avatars of `states` in view of `camera` within `nearDistance`, as
  // triangles in `out` (replaced; object ID = index into states, face ID =
  // the model's face ID).
  AvatarFrame build(const Camera& camera, float nearDistance,
                    const std::vector<AvatarState>& states, RenderGeometry& out);

  const AvatarShader& shader(uint16_t index = 0) const { return *shaders_.at(index); }

 private:
  glm::vec3 feetOf(const AvatarState& s) const;
  AvatarLight light_;
  Haze haze_;
  const RayQuery* rays_;
  AvatarShaderOptions options_;
  std::vector<std::unique_ptr<AvatarShader>> shaders_;  // per model index (null: not yet set)
  ShadedAvatar scratch_;
};

// The triangles and colours of one shaded avatar placed at `feet`, turned by
// `yawDeg`, appended to `out` (object ID `object`).
void appendAvatar(const AvatarModel& model, const ShadedAvatar& shaded, const glm::vec3& feet,
                  float yawDeg, uint32_t object, RenderGeometry& out);

}  // namespace vistream
