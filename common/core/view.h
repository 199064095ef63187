// The viewer convention every part of vistream shares: an upright viewer with
// a yaw and a pitch in degrees. Yaw 0 looks along -Z; positive yaw turns left
// (towards -X, counter-clockwise seen from above); positive pitch looks up.
// Y is up.
#pragma once

#include <cmath>
#include <glm/glm.hpp>

namespace vistream {

// The unit view direction: (-sin(yaw)cos(pitch), sin(pitch), -cos(yaw)cos(pitch)).
inline glm::dvec3 viewDirection(double yawDeg, double pitchDeg) {
  const double y = glm::radians(yawDeg), p = glm::radians(pitchDeg);
  return {-std::sin(y) * std::cos(p), std::sin(p), -std::cos(y) * std::cos(p)};
}

// The unit vector to the viewer's right, horizontal: (cos(yaw), 0, -sin(yaw)).
inline glm::dvec3 viewRight(double yawDeg) {
  const double y = glm::radians(yawDeg);
  return {std::cos(y), 0.0, -std::sin(y)};
}

}  // namespace vistream
