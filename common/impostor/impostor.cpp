#include "common/impostor/impostor.h"

#include <algorithm>
#include <cmath>

namespace vistream {

glm::vec2 SamplingPlane::textureCoordinates(const glm::vec3& eye, const glm::vec3& p) const {
  // eye + t (p - eye) on the plane: normal . (x - origin) = 0.
  const glm::vec3 d = p - eye;
  const float denominator = glm::dot(normal, d);
  glm::vec3 x = eye;
  if (std::abs(denominator) > 1e-12f * glm::dot(d, d))
    x = eye + d * (glm::dot(normal, origin - eye) / denominator);
  const glm::vec3 r = x - origin;
  return {glm::dot(r, uAxis) / glm::dot(uAxis, uAxis), glm::dot(r, vAxis) / glm::dot(vAxis, vAxis)};
}

glm::vec3 Impostor::colourAt(size_t k, const glm::vec2& st) const {
  const glm::u8vec3* t = texels.data() + firstTexel[k];
  if (singleColour[k]) return glm::vec3(t[0]);
  // Texel centres at (i + 0.5) / width: bilinear between them, clamped.
  const float x = std::clamp(st.x * float(textureWidth) - 0.5f, 0.0f, float(textureWidth - 1));
  const float y = std::clamp(st.y * float(textureHeight) - 0.5f, 0.0f, float(textureHeight - 1));
  const uint32_t i0 = std::min(uint32_t(x), textureWidth - 1);
  const uint32_t j0 = std::min(uint32_t(y), textureHeight - 1);
  const uint32_t i1 = std::min(i0 + 1, textureWidth - 1), j1 = std::min(j0 + 1, textureHeight - 1);
  const float fx = x - float(i0), fy = y - float(j0);
  auto at = [&](uint32_t i, uint32_t j) { return glm::vec3(t[j * textureWidth + i]); };
  return (at(i0, j0) * (1.0f - fx) + at(i1, j0) * fx) * (1.0f - fy) +
         (at(i0, j1) * (1.0f - fx) + at(i1, j1) * fx) * fy;
}

glm::vec3 Impostor::colourSeenFrom(size_t k, const glm::vec3& eye) const {
  if (singleColour[k]) return glm::vec3(texels[firstTexel[k]]);
  return colourAt(k, plane.textureCoordinates(eye, points[k]));
}

size_t Impostor::bytes() const {
  return points.size() * (12 + 4) + texels.size() * 3;
}

size_t Impostor::bytesUncompressed() const {
  return points.size() * (12 + 4 + size_t(textureTexels()) * 3);
}

void Impostor::boundBlocks() {
  blockBounds.assign(blockCount(), Box3f{});
  for (size_t k = 0; k < points.size(); ++k) blockBounds[k / kBlockPoints].extend(points[k]);
}

void Impostor::appendPoint(const glm::vec3& p, const glm::u8vec3* colours, bool single) {
  points.push_back(p);
  firstTexel.push_back(uint32_t(texels.size()));
  singleColour.push_back(single ? 1 : 0);
  texels.insert(texels.end(), colours, colours + (single ? 1 : textureTexels()));
}

}  // namespace vistream
