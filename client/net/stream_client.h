// The rendering client's connection to a vistream-server: Hello, then poses
// out and geometry in, on a background thread. The renderer takes snapshots
// of the triangles held so far. Everything from the server is checked: a
// Welcome that wire::validateWelcome refuses, a second Welcome, geometry that does not
// decode or has non-finite positions, or more than maxTriangles held end the
// session with a message in error(); once ended, poses are dropped.
//
// Thread safety: every public method may be called from any thread; the
// socket lives on an internal io thread.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <memory>
#include <string>

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
      50'000'000;  // the session ends if the server sends more (no unbounded memory)
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
  // Sends the viewer's pose (local frame).
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
  uint64_t version() const;  // changes whenever geometry arrives or is evicted
  uint64_t bytesReceived() const;
  size_t facesHeld() const;
  std::string error() const;  // why the session ended, empty while it runs

 private:
  struct Impl;
  std::shared_ptr<Impl> impl_;
};

}  // namespace vistream
