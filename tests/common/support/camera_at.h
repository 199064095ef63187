// A camera for client tests, set up in one call.
#pragma once

#include "client/render/camera.h"

namespace vistream::testing {

// A camera at `eye` (local frame) turned by yaw and pitch (degrees, the
// conventions of client/render/camera.h) with an image of width x height
// pixels; every other field keeps its default.
inline Camera cameraAt(glm::vec3 eye, float yawDeg, float pitchDeg, int width, int height) {
  Camera c;
  c.eye = eye;
  c.yawDeg = yawDeg;
  c.pitchDeg = pitchDeg;
  c.width = width;
  c.height = height;
  return c;
}

}  // namespace vistream::testing
