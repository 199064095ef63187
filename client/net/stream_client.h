// The rendering client's connection to a vistream-server: Hello, then poses
// out and geometry in, on a background thread. The renderer takes snapshots
// of the triangles held so far. Everything from the server is checked: a
// Welcome that wire::validateWelcome refuses, a second Welcome, geometry that does not
// decode or has non-finite positions, or more than maxTriangles held end the
// session with a message in error(); once ended, poses are dropped. A lost
// connection is made again (see StreamClientOptions::reconnect); meanwhile
// poses are dropped and what is held stays.
//
// Thread safety: every public method may be called from any thread; the
// socket lives on an internal io thread.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "client/avatar/avatar_view.h"
#include "client/render/impostor_splat.h"
#include "client/render/render_geometry.h"
#include "client/render/streamed_geometry.h"

namespace vistream {

struct StreamClientOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 7070;
  std::string token;
  float radius = 0.0f;     // near-field radius to ask for (0: the server's)
  double timeoutS = 10.0;  // for connecting and for the Welcome
  size_t maxTriangles =
      50'000'000;            // the session ends if the server sends more (no unbounded memory)
  bool wantsAvatars = true;  // other users' Avatar updates, and their models when first seen
  // Impostors of the cells the client stands in (if the server has them),
  // in place of the far faces they replace.
  bool wantsImpostors = true;
  // The session ends if the impostors held would take more memory.
  size_t maxImpostorBytes = size_t(1) << 30;
  // A connection lost after the Welcome (the server died or stopped) is
  // made again to the same address, perhaps through a proxy to another
  // replica of the same scene: backoff from 0.1 s doubling to 2 s, for at
  // most reconnectForS seconds. The Hello names the faces held, so only
  // what is missing comes; the last pose is sent again. Off: the session ends.
  bool reconnect = true;
  double reconnectForS = 30.0;
};

// An avatar model the server offers (Welcome.avatar_models) and, once it
// arrived, its glb bytes (the client asks for a model when a user first
// appears drawn as it).
struct AvatarModelOffer {
  std::string name;
  uint32_t bytes = 0;
  float heightM = 1.2f;
  std::shared_ptr<const std::string> glb;  // null until it arrived
};

class StreamClient {
 public:
  // Connects and waits for the Welcome; throws InputError (code Unreachable)
  // naming the server and the reason (refused, timed out, rejected with an
  // Error message, a Welcome that validateWelcome refuses).
  explicit StreamClient(const StreamClientOptions& options);
  ~StreamClient();  // says Bye and closes
  StreamClient(const StreamClient&) = delete;
  StreamClient& operator=(const StreamClient&) = delete;

  glm::dvec3 origin() const;  // file coordinates of the local frame
  float radius() const;       // the near-field radius the server streams within
  // Sends the viewer's pose (local frame); within one view cell at most
  // kMaxPosesPerSecond (poses in between are dropped).
  static constexpr double kMaxPosesPerSecond = 60.0;
  void sendPose(const glm::vec3& eye, float yawDeg, float pitchDeg,
                const glm::vec3& velocity = glm::vec3(0.0f));
  // Waits until the server reports the view cell of the last pose complete.
  bool waitForCell(double timeoutS);
  // The triangles held now, coloured with the server's materials.
  RenderGeometry snapshot() const;
  // What changed since the previous takeDelta() (the first: everything held,
  // with replaceAll), for a StreamedGeometry to take up; `version` is that of
  // the state it brings the consumer to. Faces are in ascending ID order.
  GeometryDelta takeDelta();
  uint64_t version() const;        // changes whenever geometry arrives or is evicted
  uint64_t bytesReceived() const;  // over every connection
  // Connections lost and (being) made again, and whether one is under way.
  uint64_t reconnects() const;
  bool reconnecting() const;
  size_t facesHeld() const;
  std::string error() const;  // why the session ended, empty while it runs

  // Other users as the latest Avatar updates report them, positions carried
  // forward at their last velocity (at most 0.6 s) and clip phases advanced
  // to now, so 2 updates a second draw as smooth walking.
  std::vector<AvatarState> avatars() const;
  std::vector<AvatarModelOffer> avatarModels() const;
  // Whether the server sends impostors (it has them and we asked).
  bool impostorsOffered() const;
  // The impostors held for the view cell holding `eye` (local frame), as
  // far as they arrived; null when none are held for that cell.
  std::shared_ptr<const ImpostorSet> impostorsAt(const glm::vec3& eye) const;
  // Impostor cells received, impostors in them, and their bytes on the wire.
  struct ImpostorFigures {
    size_t cells = 0, impostors = 0;
    uint64_t bytes = 0;
  };
  ImpostorFigures impostorFigures() const;
  // The light avatars are shaded with (Welcome.avatar_light), if sent.
  std::optional<AvatarLight> avatarLight() const;

 private:
  struct Impl;
  std::shared_ptr<Impl> impl_;
};

}  // namespace vistream
