#include "client/render/camera.h"

#include <cmath>
#include <glm/gtc/matrix_transform.hpp>

#include "common/core/view.h"

namespace vistream {

glm::vec3 Camera::forward() const {
  return glm::vec3(viewDirection(yawDeg, pitchDeg));
}

glm::vec3 Camera::right() const {
  return glm::vec3(viewRight(yawDeg));
}

glm::vec3 Camera::up() const {
  return glm::cross(right(), forward());
}

glm::mat4 Camera::view() const {
  return glm::translate(glm::lookAt(glm::vec3(0.0f), forward(), up()), -eye);
}

glm::mat4 Camera::rotationProjection() const {
  return projection() * glm::lookAt(glm::vec3(0.0f), forward(), up());
}

glm::mat4 Camera::viewProjection() const {
  return projection() * view();
}

glm::mat4 Camera::projection() const {
  return glm::perspective(glm::radians(vfovDeg), aspect(), zNear, zFar);
}

glm::vec3 Camera::rayDirection(float px, float py) const {
  return pixelRays().at(px, py);
}

Camera::PixelRays Camera::pixelRays() const {
  const float t = std::tan(0.5f * glm::radians(vfovDeg));
  const glm::vec3 r = right() * (t * aspect()), u = up() * t;
  // sx = 2 px / W - 1, sy = 1 - 2 py / H.
  return {forward() - r + u, r * (2.0f / float(width)), u * (-2.0f / float(height))};
}

float Camera::halfHfov() const {
  return std::atan(std::tan(0.5f * glm::radians(vfovDeg)) * aspect());
}

float Camera::pixelAngle() const {
  return 2.0f * std::tan(0.5f * glm::radians(vfovDeg)) / float(height);
}

}  // namespace vistream
