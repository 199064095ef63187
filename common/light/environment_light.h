// Light from the scene's environment: the diffuse irradiance a surface with a
// given normal receives from the whole sky (and ground), as 9 spherical
// harmonic coefficients per colour channel, and the radiance itself as 25
// (for radiance transfer).
//
// Method: Ramamoorthi and Hanrahan, "An Efficient Representation for
// Irradiance Environment Maps" (SIGGRAPH 2001). The radiance is projected onto
// the real spherical harmonics of orders 0 to 2; convolving with the clamped
// cosine multiplies order l by A_l (pi, 2pi/3, pi/4), and irradiance is the
// dot product with the basis at the normal. Order 2 keeps the low frequencies
// a diffuse surface responds to (their paper bounds the error at about 3% on
// average for any lighting).
//
// Sources: an equirectangular Radiance HDR image (the manifest's
// environment.hdr), or without one an analytic sky: `skyColour` at the
// zenith, lighter towards the horizon, and a dim ground below it.
//
// Directions: Y up, local frame. Pixel column u of an equirectangular image
// (0 at the left edge, 1 at the right) is azimuth atan2(x, -z) = 2 pi (u -
// 0.5), so the image's centre is -Z, where yaw 0 looks; row v (0 at the top)
// is polar angle pi v from +Y.
//
// Thread safety: immutable after construction.
#pragma once

#include <array>
#include <filesystem>
#include <functional>
#include <glm/glm.hpp>
#include <string>

#include "common/scene/scene.h"

namespace vistream {

// The 9 real spherical harmonics of orders 0..2 at unit direction d.
std::array<float, 9> shBasis(const glm::vec3& d);

class EnvironmentLight {
 public:
  // Projects radiance(dir) over the sphere, sampled on a `width` x `width/2`
  // equirectangular grid.
  static EnvironmentLight project(const std::function<glm::vec3(const glm::vec3&)>& radiance,
                                  int width, std::string source);
  // From an equirectangular Radiance HDR file; throws InputError naming the
  // file if it cannot be read.
  static EnvironmentLight fromHdr(const std::filesystem::path& file);
  // The analytic sky for a scene without an HDR image.
  static EnvironmentLight sky(const glm::vec3& skyColour);
  // A scene's: its HDR image, or the analytic sky of its sky colour.
  static EnvironmentLight of(const Environment& environment);

  // Irradiance (linear RGB, the radiance's units times steradians) on a
  // surface with unit normal n. Clamped at 0 (order 2 can ring negative on
  // very uneven lighting).
  glm::vec3 irradiance(const glm::vec3& n) const;
  // Mean radiance of the band within 10 degrees above the horizon: the colour
  // a distant view fades into (background and haze).
  const glm::vec3& horizonRadiance() const { return horizon_; }
  // The radiance's own projection onto the 25 real spherical harmonics of
  // orders 0..4 (spherical_harmonics.h), linear RGB: what transfer vectors
  // (common/avatar/transfer.h) are dotted with.
  const std::array<glm::vec3, 25>& radiance() const { return radiance_; }
  // Exitant radiance of a transfer vector (shTerms(orders) coefficients):
  // sum of t_i L_i, per channel, clamped at 0.
  glm::vec3 transferred(const float* transfer, int orders) const;
  // "hdr: FILE" or "analytic sky".
  const std::string& source() const { return source_; }

 private:
  std::array<glm::vec3, 9> coeff_{};  // radiance coefficients times A_l
  std::array<glm::vec3, 25> radiance_{};
  glm::vec3 horizon_{0.0f};
  std::string source_;
};

}  // namespace vistream
