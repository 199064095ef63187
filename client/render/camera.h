// The upright pinhole camera every client renderer shares.
//
// One camera, one set of matrices: the OpenGL near field, the software
// rasterizer, the horizon tracer, the image cache and the ray caster all
// derive their pixel geometry from here, so a pixel means the same direction
// in each of them and the near-field/far-field border cannot show.
//
// Conventions (see common/generate/path.h): Y up, yaw 0 looks along -Z,
// positive yaw turns left, positive pitch looks up, no roll (upright viewer).
// Pixel (x, y) has its centre at (x + 0.5, y + 0.5); row 0 is the top row.
// Positions are in the scene's local frame.
#pragma once

#include <glm/glm.hpp>

namespace vistream {

struct Camera {
  glm::vec3 eye{0.0f};
  float yawDeg = 0.0f;
  float pitchDeg = 0.0f;
  float vfovDeg = 60.0f;  // vertical field of view
  int width = 640, height = 480;
  float zNear = 0.1f;
  float zFar = 1.0e5f;  // far enough for any scene; depth precision is not needed beyond it

  float aspect() const { return float(width) / float(height); }
  // Camera basis: forward (unit view direction), right (horizontal), up.
  glm::vec3 forward() const;
  glm::vec3 right() const;
  glm::vec3 up() const;
  glm::mat4 view() const;
  glm::mat4 projection() const;  // OpenGL clip space, depth in [-1, 1]
  glm::mat4 viewProjection() const;
  // projection() times the view rotation, without the translation: apply it
  // to (p - eye). Far from the origin this keeps the float error of the eye
  // position out of the view axis (every renderer transforms this way).
  glm::mat4 rotationProjection() const;

  // The (unnormalised) direction of the ray through pixel coordinates (px, py)
  // in window space, row 0 at the top; a pixel centre is (x + 0.5, y + 0.5).
  // Its component along forward() is 1.
  glm::vec3 rayDirection(float px, float py) const;

  // rayDirection() for many pixels: the basis is computed once.
  struct PixelRays {
    glm::vec3 origin, perX, perY;  // direction = origin + px * perX + py * perY
    glm::vec3 at(float px, float py) const { return origin + px * perX + py * perY; }
  };
  PixelRays pixelRays() const;
  // Horizontal half field of view, radians.
  float halfHfov() const;
  // The angle one pixel spans at the image centre, radians.
  float pixelAngle() const;
};

}  // namespace vistream
