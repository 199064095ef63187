// The impostor encoding (protocol/impostor): a quantized impostor comes back
// exactly, any other within half a step of its perspective grid (checked in
// the test's own angles and depths), it is smaller than the representation
// in memory, and cut, altered or hostile bytes are refused with an error,
// never a crash.
#include "protocol/impostor/impostor_codec.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <optional>
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

// Decoded point k's index in `in`, by the ID in its first texel.
std::vector<size_t> matchById(const Impostor& in, const Impostor& out) {
  std::map<uint32_t, size_t> byId;
  for (size_t k = 0; k < out.size(); ++k) {
    const glm::u8vec3 c = out.texels[out.firstTexel[k]];
    byId[uint32_t(c.x) | uint32_t(c.y) << 8 | uint32_t(c.z) << 16] = k;
  }
  std::vector<size_t> match(in.size());
  EXPECT_EQ(byId.size(), in.size());
  for (size_t k = 0; k < in.size(); ++k) match[k] = byId.at(uint32_t(k));
  return match;
}

TEST(ImpostorCodec, GivesBackEveryPointWithinHalfAGridStepAndEveryTexelExactly) {
  Impostor in = sampleImpostor(5000);
  in.angleStep = 2e-4f;
  in.logDepthStep = 1e-3f;
  const std::vector<uint8_t> bytes = encodeImpostor(in);
  Impostor out;
  std::string error;
  ASSERT_TRUE(decodeImpostor(bytes, out, error)) << error;
  EXPECT_EQ(out.cell.lo, in.cell.lo);
  EXPECT_EQ(out.box.hi, in.box.hi);
  EXPECT_EQ(out.plane.vAxis, in.plane.vAxis);
  EXPECT_EQ(out.cameras[2], in.cameras[2]);
  EXPECT_EQ(out.angleStep, in.angleStep);
  EXPECT_EQ(out.logDepthStep, in.logDepthStep);
  ASSERT_EQ(out.size(), in.size());
  const std::vector<size_t> match = matchById(in, out);
  // The sample's plane faces -z from the cell's centre, its u axis along x:
  // a point's angles are x / depth and y / depth, its depth -z.
  const glm::vec3 c = in.cell.center();
  auto angles = [&](const glm::vec3& p) {
    const float depth = c.z - p.z;
    return glm::vec3((p.x - c.x) / depth, (p.y - c.y) / depth, std::log(depth));
  };
  for (size_t k = 0; k < in.size(); ++k) {
    const size_t d = match[k];
    const glm::vec3 error3 = glm::abs(angles(out.points[d]) - angles(in.points[k]));
    ASSERT_LE(error3.x, 0.5f * in.angleStep * 1.001f + 1e-6f) << k;
    ASSERT_LE(error3.y, 0.5f * in.angleStep * 1.001f + 1e-6f) << k;
    ASSERT_LE(error3.z, 0.5f * in.logDepthStep * 1.001f + 1e-6f) << k;
    ASSERT_EQ(out.singleColour[d], in.singleColour[k]);
    const uint32_t texels = in.singleColour[k] ? 1 : in.textureTexels();
    for (uint32_t i = 0; i < texels; ++i)
      ASSERT_EQ(out.texels[out.firstTexel[d] + i], in.texels[in.firstTexel[k] + i]);
    // The colour seen from anywhere is the same function.
    ASSERT_EQ(out.colourAt(d, {0.3f, 0.8f}), in.colourAt(k, {0.3f, 0.8f}));
  }
}

TEST(ImpostorCodec, GivesBackAQuantizedImpostorExactlyWithTexturesOnItsColourStep) {
  Impostor in = sampleImpostor(3000);
  in.angleStep = 5e-4f;
  in.logDepthStep = 2e-3f;
  in.colourStep = 8;
  const Impostor raw = in;
  in.quantize();
  Impostor again = in;
  again.quantize();
  EXPECT_EQ(again.points, in.points) << "quantize is idempotent";
  EXPECT_EQ(again.texels, in.texels);
  Impostor out;
  std::string error;
  ASSERT_TRUE(decodeImpostor(encodeImpostor(in), out, error)) << error;
  ASSERT_EQ(out.size(), in.size());
  EXPECT_EQ(out.colourStep, 8u);
  // Points are distinct grid points: match them by position, exactly.
  std::map<std::array<float, 3>, size_t> byPosition;
  for (size_t k = 0; k < out.size(); ++k)
    byPosition[{out.points[k].x, out.points[k].y, out.points[k].z}] = k;
  ASSERT_EQ(byPosition.size(), in.size());
  for (size_t k = 0; k < in.size(); ++k) {
    const auto it = byPosition.find({in.points[k].x, in.points[k].y, in.points[k].z});
    ASSERT_NE(it, byPosition.end()) << k;
    const size_t d = it->second;
    ASSERT_EQ(out.singleColour[d], in.singleColour[k]);
    const uint32_t texels = in.singleColour[k] ? 1 : in.textureTexels();
    for (uint32_t i = 0; i < texels; ++i) {
      const glm::u8vec3 t = out.texels[out.firstTexel[d] + i];
      ASSERT_EQ(t, in.texels[in.firstTexel[k] + i]);
      const glm::u8vec3 before = raw.texels[raw.firstTexel[k] + i];
      for (int ch = 0; ch < 3; ++ch) {
        if (in.singleColour[k]) {
          ASSERT_EQ(t[ch], before[ch]) << "single colours stay exact";
        } else {
          ASSERT_TRUE(t[ch] % 8 == 0 || t[ch] == 255) << int(t[ch]);
          ASSERT_LE(std::abs(int(t[ch]) - int(before[ch])), 4);
        }
      }
    }
  }
}

TEST(ImpostorCodec, SnapsEveryLevelToTheNearestStepAndKeepsTheSnappedOnes) {
  for (uint32_t step : {1u, 2u, 4u, 8u, 16u})
    for (int v = 0; v < 256; ++v) {
      const uint8_t snapped = Impostor::snapLevel(uint8_t(v), step);
      EXPECT_TRUE(snapped % step == 0 || snapped == 255) << v << " " << step;
      // The nearest multiple, or 255 for the top one past it.
      EXPECT_LE(std::abs(int(snapped) - v), int(step / 2)) << v << " " << step;
      EXPECT_EQ(Impostor::snapLevel(snapped, step), snapped) << v << " " << step;
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

TEST(ImpostorCodec,
     KeepsItsGridOrthonormalOnASubnormalSamplingPlaneSoWhatDecodesEncodesBackToItself) {
  // A plane whose horizontal axis is subnormal (its squared length
  // underflows) and whose normal leans a hair off -Z: the bytes a fuzzer found.
  Impostor imp = sampleImpostor(300);
  imp.plane.uAxis = {-7.94e-23f, 2.8e-45f, 0.0f};
  imp.plane.normal = {-1.08e-19f, 4.88e-4f, -1.0f};
  const std::optional<PointGrid> grid = imp.pointGrid();
  ASSERT_TRUE(grid.has_value());
  EXPECT_NEAR(glm::length(grid->e1), 1.0f, 1e-6f);
  EXPECT_NEAR(glm::length(grid->e2), 1.0f, 1e-6f);
  EXPECT_NEAR(glm::length(grid->normal), 1.0f, 1e-6f);
  EXPECT_NEAR(glm::dot(grid->e1, grid->normal), 0.0f, 1e-6f);
  EXPECT_NEAR(glm::dot(grid->e2, grid->normal), 0.0f, 1e-6f);
  EXPECT_NEAR(glm::dot(grid->e1, grid->e2), 0.0f, 1e-6f);
  // Every grid point's coordinates are its own.
  std::mt19937 rng(11);
  for (int i = 0; i < 1000; ++i) {
    std::array<uint32_t, 3> q{};
    for (size_t a = 0; a < 3; ++a) q[a] = uint32_t(rng() % (grid->steps[a] + 1));
    const std::array<uint32_t, 3> back = grid->coordinates(grid->point(q));
    for (size_t a = 0; a < 3; ++a)
      EXPECT_LE(std::abs(int64_t(back[a]) - int64_t(q[a])), 1) << "axis " << a << " of " << q[a];
  }
  // Decoded once, the points lie on the grid: encoded and decoded again,
  // they come back unchanged.
  Impostor once, twice;
  std::string error;
  ASSERT_TRUE(decodeImpostor(encodeImpostor(imp), once, error)) << error;
  ASSERT_TRUE(decodeImpostor(encodeImpostor(once), twice, error)) << error;
  ASSERT_EQ(twice.size(), imp.size());
  const std::vector<size_t> first = matchById(imp, once), second = matchById(imp, twice);
  for (size_t k = 0; k < imp.size(); ++k) {
    EXPECT_LE(glm::length(once.points[first[k]] - imp.points[k]), grid->slack) << k;
    EXPECT_LE(glm::length(twice.points[second[k]] - once.points[first[k]]), grid->slack) << k;
  }
}

TEST(ImpostorCodec, KeepsItsGridOrthonormalWhenTheAxisLeansAlmostOntoTheNormal) {
  // A horizontal axis less than a degree off the normal (the bytes a fuzzer
  // found): in float, the axis left after taking out the normal lost most
  // of its bits, the frame was off by 1e-5 and a decoded point, encoded
  // again, landed outside its box.
  for (const float lean : {0.0125f, 1e-3f, 2e-5f}) {
    Impostor imp = sampleImpostor(300);
    // A normal off every axis (so that adding the lean rounds), still
    // facing the box.
    const glm::vec3 axisNormal = glm::normalize(imp.plane.normal);
    const glm::vec3 across = glm::normalize(glm::cross(axisNormal, glm::vec3(0.0f, 1.0f, 0.0f)));
    const glm::vec3 n =
        glm::normalize(axisNormal + 0.0173f * across + 0.0119f * glm::vec3(0.0f, 1.0f, 0.0f));
    imp.plane.normal = n;
    const glm::vec3 side = glm::normalize(glm::cross(n, glm::vec3(0.0f, 1.0f, 0.0f)));
    imp.plane.uAxis = n + lean * side;
    const std::optional<PointGrid> grid = imp.pointGrid();
    ASSERT_TRUE(grid.has_value()) << lean;
    EXPECT_NEAR(glm::length(grid->e1), 1.0f, 1e-6f) << lean;
    EXPECT_NEAR(glm::length(grid->e2), 1.0f, 1e-6f) << lean;
    EXPECT_NEAR(glm::dot(grid->e1, grid->normal), 0.0f, 1e-6f) << lean;
    EXPECT_NEAR(glm::dot(grid->e2, grid->normal), 0.0f, 1e-6f) << lean;
    EXPECT_NEAR(glm::dot(grid->e1, grid->e2), 0.0f, 1e-6f) << lean;
    // The axis keeps its side of the normal.
    EXPECT_GT(glm::dot(grid->e1, side), 0.999f) << lean;
    Impostor once, twice;
    std::string error;
    ASSERT_TRUE(decodeImpostor(encodeImpostor(imp), once, error)) << lean << ": " << error;
    ASSERT_TRUE(decodeImpostor(encodeImpostor(once), twice, error)) << lean << ": " << error;
    ASSERT_EQ(twice.size(), imp.size());
    const std::vector<size_t> first = matchById(imp, once), second = matchById(imp, twice);
    for (size_t k = 0; k < imp.size(); ++k) {
      EXPECT_LE(glm::length(once.points[first[k]] - imp.points[k]), grid->slack) << k;
      EXPECT_LE(glm::length(twice.points[second[k]] - once.points[first[k]]), grid->slack) << k;
    }
  }
}

TEST(ImpostorCodec, PullsAPointJustPastItsBoxBackWithinTheSlackAndRefusesOneFarOutside) {
  // The sample's box spans x -75..75; its corners' directions from the cell
  // span tangents up to 75/168, so points at x = 75 + a few slacks, 220 m
  // away (tangent 0.34), still lie inside the grid.
  Impostor imp = sampleImpostor(3);
  const std::optional<PointGrid> grid = imp.pointGrid();
  ASSERT_TRUE(grid.has_value());
  const float slack = grid->slack;
  ASSERT_GT(slack, 0.0f);
  ASSERT_LT(slack, 0.1f);
  imp.points[1] = {75.0f + 3.0f * slack, 20.0f, -220.0f};  // past the slack, within four
  Impostor out, again;
  std::string error;
  ASSERT_TRUE(decodeImpostor(encodeImpostor(imp), out, error)) << error;
  const std::vector<size_t> match = matchById(imp, out);
  // Pulled back onto the slack's face; the other coordinates within a grid step.
  EXPECT_FLOAT_EQ(out.points[match[1]].x, 75.0f + slack);
  EXPECT_NEAR(out.points[match[1]].y, 20.0f, slack);
  EXPECT_NEAR(out.points[match[1]].z, -220.0f, slack);
  // Encoded again, it decodes again.
  ASSERT_TRUE(decodeImpostor(encodeImpostor(out), again, error)) << error;
  EXPECT_EQ(again.size(), imp.size());
  // Ten slacks out is no rounding: refused.
  imp.points[1].x = 75.0f + 10.0f * slack;
  error.clear();
  EXPECT_FALSE(decodeImpostor(encodeImpostor(imp), out, error));
  EXPECT_NE(error.find("outside the box"), std::string::npos) << error;
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
  // A tiny impostor's sections are stored raw: alter its header and body.
  const Impostor tiny = sampleImpostor(2);
  const std::vector<uint8_t> raw = encodeImpostor(tiny);
  ASSERT_TRUE(decodeImpostor(raw, out, error)) << error;
  const size_t countAt = 6 + 35 * 4 + 3;  // after the floats and the three bytes
  // A point count more than the positions can hold.
  b = raw;
  b[countAt] = 0xff;
  b.insert(b.begin() + long(countAt) + 1, {0xff, 0x7f});
  refused(b, "points in");
  // A texture size and a colour step out of range.
  b = raw;
  b[countAt - 2] = 0;
  refused(b, "texture 0x2");
  b = raw;
  b[countAt - 3] = 3;
  refused(b, "colour step 3");
  // A box behind the cell's centre.
  b = raw;
  const float behind = 30.0f;  // the box's hi.z: the box now reaches behind the cell (z -2..2)
  std::memcpy(b.data() + 6 + 11 * 4, &behind, 4);
  refused(b, "in front of the cell");
  // A section with an unknown mode, and bytes left over after the textures.
  b = raw;
  b[countAt + 2] = 7;  // the positions' mode, after their one-byte length
  refused(b, "mode 7");
  b = raw;
  b.push_back(7);
  refused(b, "after the textures");
}

}  // namespace
}  // namespace vistream::wire
