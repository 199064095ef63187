// The impostor encoding (protocol/impostor): what goes in comes back (points
// within half a quantization step, texels exact), it is smaller than the
// representation in memory, and cut, altered or hostile bytes are refused
// with an error, never a crash.
#include "protocol/impostor/impostor_codec.h"

#include <gtest/gtest.h>

#include <map>
#include <random>

#include "protocol/geometry/byte_coding.h"

namespace vistream::wire {
namespace {

// An impostor of `n` points in a 150 x 40 x 90 m box; each point's first
// texel is unique (its index in 24 bits), so a decoded point can be matched
// to its original. Every third point is single-coloured; the textured ones
// vary smoothly across their texels, as baked textures do.
Impostor sampleImpostor(size_t n, uint32_t width = 8, uint32_t height = 2) {
  Impostor imp;
  imp.cell = Box3f({-2.0f, 1.0f, -2.0f}, {2.0f, 3.0f, 2.0f});
  imp.box = Box3f({-75.0f, 0.0f, -260.0f}, {75.0f, 40.0f, -170.0f});
  imp.plane.origin = {-3.0f, 0.5f, -2.0f};
  imp.plane.uAxis = {6.0f, 0.0f, 0.0f};
  imp.plane.vAxis = {0.0f, 3.0f, 0.0f};
  imp.cameras = {glm::vec3(-6, 4, -2), glm::vec3(6, 4, -2), glm::vec3(0, -3, -2)};
  imp.textureWidth = width;
  imp.textureHeight = height;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::vector<glm::u8vec3> texture(width * height);
  for (size_t k = 0; k < n; ++k) {
    const glm::vec3 p = imp.box.lo + glm::vec3(unit(rng), unit(rng), unit(rng)) * imp.box.extent();
    const glm::u8vec3 id(uint8_t(k), uint8_t(k >> 8), uint8_t(k >> 16));
    for (uint32_t i = 0; i < texture.size(); ++i)
      texture[i] = id + glm::u8vec3(uint8_t(3 * i), uint8_t(i), uint8_t(250 + i));
    texture[0] = id;
    imp.appendPoint(p, texture.data(), k % 3 == 0);
  }
  return imp;
}

TEST(ImpostorCodec, GivesBackEveryPointWithinHalfAStepAndEveryTexelExactly) {
  const Impostor in = sampleImpostor(5000);
  const std::vector<uint8_t> bytes = encodeImpostor(in);
  Impostor out;
  std::string error;
  ASSERT_TRUE(decodeImpostor(bytes, out, error)) << error;
  EXPECT_EQ(out.cell.lo, in.cell.lo);
  EXPECT_EQ(out.box.hi, in.box.hi);
  EXPECT_EQ(out.plane.vAxis, in.plane.vAxis);
  EXPECT_EQ(out.cameras[2], in.cameras[2]);
  ASSERT_EQ(out.size(), in.size());
  const glm::vec3 halfStep = in.box.extent() / 131070.0f;
  std::map<uint32_t, size_t> byId;
  for (size_t k = 0; k < out.size(); ++k) {
    const glm::u8vec3 c = out.texels[out.firstTexel[k]];
    byId[uint32_t(c.x) | uint32_t(c.y) << 8 | uint32_t(c.z) << 16] = k;
  }
  ASSERT_EQ(byId.size(), in.size());
  for (size_t k = 0; k < in.size(); ++k) {
    const size_t d = byId.at(uint32_t(k));
    for (int a = 0; a < 3; ++a)
      ASSERT_LE(std::abs(out.points[d][a] - in.points[k][a]), halfStep[a] * 1.01f + 1e-5f);
    ASSERT_EQ(out.singleColour[d], in.singleColour[k]);
    const uint32_t texels = in.singleColour[k] ? 1 : in.textureTexels();
    for (uint32_t i = 0; i < texels; ++i)
      ASSERT_EQ(out.texels[out.firstTexel[d] + i], in.texels[in.firstTexel[k] + i]);
    // The colour seen from anywhere is the same function.
    ASSERT_EQ(out.colourAt(d, {0.3f, 0.8f}), in.colourAt(k, {0.3f, 0.8f}));
  }
}

TEST(ImpostorCodec, IsSmallerThanTheImpostorInMemory) {
  const Impostor in = sampleImpostor(20000);
  EXPECT_LT(encodeImpostor(in).size(), in.bytes() * 3 / 4);
  // The empty impostor and the 1x1 texture are still impostors.
  for (const Impostor& edge : {sampleImpostor(0), sampleImpostor(300, 1, 1)}) {
    Impostor out;
    std::string error;
    ASSERT_TRUE(decodeImpostor(encodeImpostor(edge), out, error)) << error;
    EXPECT_EQ(out.size(), edge.size());
  }
}

TEST(ImpostorCodec, RefusesCutAlteredAndHostileBytesNamingWhatIsWrong) {
  const std::vector<uint8_t> bytes = encodeImpostor(sampleImpostor(400));
  Impostor out;
  std::string error;
  // Every cut is refused.
  for (size_t n = 0; n < bytes.size(); n += 1 + n / 50) {
    error.clear();
    EXPECT_FALSE(decodeImpostor(std::span(bytes.data(), n), out, error)) << n;
    EXPECT_FALSE(error.empty());
  }
  auto refused = [&](std::vector<uint8_t> b, const std::string& mention) {
    error.clear();
    EXPECT_FALSE(decodeImpostor(b, out, error));
    EXPECT_NE(error.find(mention), std::string::npos) << error;
  };
  std::vector<uint8_t> b = bytes;
  b[0] = 'X';
  refused(b, "VIMP");
  b = bytes;
  b[4] = 9;
  refused(b, "version 9");
  b = bytes;
  b[5] = 0x80;
  refused(b, "flags");
  // The same impostor with its body uncompressed (flags 0), to alter.
  auto uncompressed = [](const Impostor& imp) {
    std::vector<uint8_t> z = encodeImpostor(imp);
    if (z[5] == 0) return z;
    std::string why;
    const auto body = zstdDecompress(std::span(z).subspan(6), 1u << 20, why);
    EXPECT_TRUE(body.has_value()) << why;
    std::vector<uint8_t> raw(z.begin(), z.begin() + 6);
    raw[5] = 0;
    raw.insert(raw.end(), body->begin(), body->end());
    return raw;
  };
  const Impostor tiny = sampleImpostor(2);
  std::vector<uint8_t> raw = uncompressed(tiny);
  ASSERT_TRUE(decodeImpostor(raw, out, error)) << error;
  // A point count more than the body's bytes can hold.
  const size_t countAt = 6 + 33 * 4 + 2;
  raw[countAt] = 0xff;
  raw.insert(raw.begin() + long(countAt) + 1, {0xff, 0x7f});
  refused(raw, "point count");
  // A texture size out of range.
  raw = uncompressed(tiny);
  raw[countAt - 2] = 0;
  refused(raw, "texture 0x2");
  // Bytes left over after the colours.
  raw = uncompressed(tiny);
  raw.push_back(7);
  refused(raw, "after the colours");
}

}  // namespace
}  // namespace vistream::wire
