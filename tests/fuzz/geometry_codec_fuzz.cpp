// libFuzzer target: the Geometry payload decoder (protocol/geometry) must
// refuse any bytes with an error or decode them to a batch that keeps its own
// bounds, never crash, hang or allocate without bound. The first byte picks
// the codec (bit 0) and the compression (bit 1), the rest is the payload, so
// (bit 2 set: the rest is a lighting section, its second byte the triangle
// count)
// the fuzzer reaches the varints, zstd and meshoptimizer's decoders without a
// FlatBuffer around them (frame_decoder_fuzz covers that way in).
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <string>

#include "protocol/geometry/geometry_codec.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vistream::wire;
  if (size == 0) return 0;
  if (data[0] & 4) {  // the lighting section, for data[1] triangles
    if (size < 2) return 0;
    DecodedGeometry lit;
    std::string why;
    if (!decodeGeometryLighting(std::span(data + 2, size - 2), data[1], lit, why)) {
      if (why.empty() || !lit.colours.empty()) std::abort();
      return 0;
    }
    size_t points = 0;
    for (uint8_t n : lit.levels) points += (size_t(n) + 1) * (size_t(n) + 2) / 2;
    if (lit.levels.size() != data[1] || lit.colours.size() != points) std::abort();
    return 0;
  }
  const GeometryCodec codec = data[0] & 1 ? GeometryCodec::Varint : GeometryCodec::Meshopt;
  const GeometryCompression compression =
      data[0] & 2 ? GeometryCompression::Zstd : GeometryCompression::None;
  const QuantizationGrid grid{glm::dvec3(-500.0, -10.0, -500.0), 1e-3};
  DecodedGeometry out;
  std::string error;
  if (!decodeGeometryPayload(std::span(data + 1, size - 1), codec, compression, grid, out, error)) {
    if (error.empty()) std::abort();  // a refusal always says why
    return 0;
  }
  // What every decoded batch promises its user.
  if (out.materials.size() != out.faces.size() || out.triangleCounts.size() != out.faces.size())
    std::abort();
  size_t triangles = 0;
  for (uint16_t t : out.triangleCounts) triangles += t;
  if (out.indices.size() != 3 * triangles) std::abort();
  for (uint32_t i : out.indices)
    if (i >= out.positions.size()) std::abort();
  for (size_t i = 1; i < out.faces.size(); ++i)
    if (out.faces[i] < out.faces[i - 1]) std::abort();
  return 0;
}
