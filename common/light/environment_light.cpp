#include "common/light/environment_light.h"

#include <stb_image.h>

#include <cmath>
#include <memory>
#include <numbers>

#include "common/core/error.h"
#include "common/light/spherical_harmonics.h"

namespace vistream {
namespace {

// The clamped cosine's convolution weights by order (Ramamoorthi and Hanrahan, eq. 8).
constexpr float kA0 = std::numbers::pi_v<float>, kA1 = 2.0f * std::numbers::pi_v<float> / 3.0f,
                kA2 = std::numbers::pi_v<float> / 4.0f;

// Pi as the equirectangular mapping has always taken it: the float's value.
constexpr double kEquirectPi = double(std::numbers::pi_v<float>);

// Unit direction of the centre of equirectangular texel (u, v) in [0, 1]^2.
glm::vec3 equirectDirection(double u, double v) {
  const double phi = 2.0 * kEquirectPi * (u - 0.5);  // azimuth, 0 at -Z
  const double theta = kEquirectPi * v;              // polar angle from +Y
  return glm::vec3(float(std::sin(theta) * std::sin(phi)), float(std::cos(theta)),
                   float(-std::sin(theta) * std::cos(phi)));
}

}  // namespace

std::array<float, 9> shBasis(const glm::vec3& d) {
  std::array<float, 9> y;
  shEvaluate(d, 3, y.data());
  return y;
}

EnvironmentLight EnvironmentLight::project(
    const std::function<glm::vec3(const glm::vec3&)>& radiance, int width, std::string source) {
  EnvironmentLight e;
  e.source_ = std::move(source);
  const int height = std::max(1, width / 2);
  std::array<glm::dvec3, 25> sum{};
  glm::dvec3 horizon(0.0);
  double horizonWeight = 0.0;
  for (int row = 0; row < height; ++row) {
    const double v = (row + 0.5) / height;
    const double theta = kEquirectPi * v;
    // Solid angle of one texel of this row.
    const double dOmega = (2.0 * kEquirectPi / width) * (kEquirectPi / height) * std::sin(theta);
    const bool nearHorizon = theta < kEquirectPi / 2.0 && theta > kEquirectPi * (80.0 / 180.0);
    for (int col = 0; col < width; ++col) {
      const glm::vec3 d = equirectDirection((col + 0.5) / width, v);
      const glm::dvec3 l = glm::dvec3(radiance(d));
      float y[25];
      shEvaluate(d, 5, y);
      for (size_t k = 0; k < 25; ++k) sum[k] += l * double(y[k]) * dOmega;
      if (nearHorizon) {
        horizon += l * dOmega;
        horizonWeight += dOmega;
      }
    }
  }
  const float a[9] = {kA0, kA1, kA1, kA1, kA2, kA2, kA2, kA2, kA2};
  for (size_t k = 0; k < 9; ++k) e.coeff_[k] = glm::vec3(sum[k]) * a[k];
  for (size_t k = 0; k < 25; ++k) e.radiance_[k] = glm::vec3(sum[k]);
  e.horizon_ = horizonWeight > 0.0 ? glm::vec3(horizon / horizonWeight) : glm::vec3(0.0f);
  return e;
}

EnvironmentLight EnvironmentLight::fromHdr(const std::filesystem::path& file) {
  int w = 0, h = 0, channels = 0;
  std::unique_ptr<float, void (*)(void*)> pixels(
      stbi_loadf(file.string().c_str(), &w, &h, &channels, 3), stbi_image_free);
  if (!pixels)
    throwInputError("{}: cannot read the HDR environment: {}", file.string(),
                    stbi_failure_reason() ? stbi_failure_reason() : "unknown error");
  if (w < 2 || h < 1)
    throwInputError("{}: an HDR environment of {}x{} pixels is too small", file.string(), w, h);
  const float* p = pixels.get();
  // Nearest texel: the projection visits each texel of a grid of the image's
  // own width once, so this is the image's own sampling.
  auto radiance = [&](const glm::vec3& d) {
    const double u = 0.5 + std::atan2(double(d.x), -double(d.z)) / (2.0 * kEquirectPi);
    const double v = std::acos(std::clamp(double(d.y), -1.0, 1.0)) / kEquirectPi;
    const int x = std::clamp(int(u * w), 0, w - 1), y = std::clamp(int(v * h), 0, h - 1);
    const float* t = p + 3 * (size_t(y) * size_t(w) + size_t(x));
    glm::vec3 c(t[0], t[1], t[2]);
    for (int k = 0; k < 3; ++k)  // a NaN or infinite texel (corrupt file) counts as black
      if (!std::isfinite(c[k]) || c[k] < 0.0f) c[k] = 0.0f;
    return c;
  };
  return project(radiance, w, "hdr: " + file.filename().string());
}

EnvironmentLight EnvironmentLight::sky(const glm::vec3& skyColour) {
  const glm::vec3 horizon = glm::mix(skyColour, glm::vec3(1.0f), 0.5f);
  const float grey = glm::dot(skyColour, glm::vec3(0.2126f, 0.7152f, 0.0722f));
  const glm::vec3 ground = 0.3f * grey * glm::vec3(1.0f, 0.95f, 0.85f);
  auto radiance = [&](const glm::vec3& d) {
    return d.y >= 0.0f ? glm::mix(horizon, skyColour, std::sqrt(d.y)) : ground;
  };
  return project(radiance, 256, "analytic sky");
}

EnvironmentLight EnvironmentLight::of(const Environment& environment) {
  return environment.hdrImage.empty() ? sky(environment.skyColor) : fromHdr(environment.hdrImage);
}

glm::vec3 EnvironmentLight::irradiance(const glm::vec3& n) const {
  const auto y = shBasis(n);
  glm::vec3 e(0.0f);
  for (size_t k = 0; k < 9; ++k) e += coeff_[k] * y[k];
  return glm::max(e, glm::vec3(0.0f));
}

glm::vec3 EnvironmentLight::transferred(const float* transfer, int orders) const {
  glm::vec3 c(0.0f);
  for (int i = 0; i < shTerms(orders); ++i) c += radiance_[size_t(i)] * transfer[i];
  return glm::max(c, glm::vec3(0.0f));
}

}  // namespace vistream
