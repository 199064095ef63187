#include "common/avatar/transfer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "common/avatar/self_shadow.h"
#include "common/light/spherical_harmonics.h"
#include "tests/common/support/random_directions.h"

namespace vistream {
namespace {

// The clamped cosine about unit n, projected (the zonal rotation theorem):
// T_lm = z_l sqrt(4 pi / (2l + 1)) Y_lm(n).
std::vector<double> openTransfer(const glm::vec3& n) {
  float y[25];
  shEvaluate(n, 5, y);
  std::vector<double> t(25);
  for (int l = 0; l <= 4; ++l)
    for (int m = -l; m <= l; ++m)
      t[size_t(l * (l + 1) + m)] = clampedCosineZonal(l) *
                                   std::sqrt(4 * std::numbers::pi / (2 * l + 1)) *
                                   y[l * (l + 1) + m];
  return t;
}

double relativeL2(const float* got, const std::vector<double>& want, int terms) {
  double num = 0, den = 0;
  for (int i = 0; i < terms; ++i) {
    num += (got[i] - want[size_t(i)]) * (got[i] - want[size_t(i)]);
    den += want[size_t(i)] * want[size_t(i)];
  }
  return std::sqrt(num / den);
}

using testing::randomDirections;

TEST(Transfer, AnOpenHemisphereGivesTheRotatedClampedCosine) {
  for (const bool downsample : {false, true}) {
    const TransferIntegrator integrator(32, {5, downsample});
    const VisibilityMask open(32);
    for (const glm::vec3& n : randomDirections(50)) {
      float t[25];
      integrator.diffuse(open, TangentFrame::around(n), t);
      EXPECT_LT(relativeL2(t, openTransfer(n), 25), 0.02) << "downsample " << downsample;
    }
  }
}

TEST(Transfer, AFinerMaskConvergesToTheRotatedClampedCosine) {
  const glm::vec3 n = glm::normalize(glm::vec3(0.3f, -0.5f, 0.8f));
  double previous = 1.0;
  for (const int side : {16, 32, 64, 128}) {
    const TransferIntegrator integrator(side, {5, false});
    float t[25];
    integrator.diffuse(VisibilityMask(side), TangentFrame::around(n), t);
    const double e = relativeL2(t, openTransfer(n), 25);
    EXPECT_LT(e, previous) << side;
    previous = e;
  }
  EXPECT_LT(previous, 0.005);
}

TEST(Transfer, AFullyBlockedMaskTransfersNothing) {
  const TransferIntegrator integrator(32);
  VisibilityMask mask(32);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) mask.set(x, y);
  float t[25];
  integrator.diffuse(mask, TangentFrame::around({0, 1, 0}), t);
  for (const float v : t) EXPECT_EQ(v, 0.0f);
}

// A sphere of radius 1 centred 2 above the vertex hides the cone of
// half-angle 30 degrees around the normal: the open part's projection is
// Y_0 (pi - pi sin^2 30) and Y_1^0 2 pi cos^3(30) / 3, the rest 0 by
// symmetry. The mask's pixel quadrature errs by a few percent at 32 x 32
// and converges with finer masks.
TEST(Transfer, ASphereAboveTheVertexLeavesTheAnalyticRing) {
  const double c30 = std::cos(std::numbers::pi / 6);
  const double want0 = 0.282095 * (std::numbers::pi - std::numbers::pi * 0.25),
               want2 = 0.488603 * 2 * std::numbers::pi * c30 * c30 * c30 / 3;
  double previous = 1.0;
  for (const int side : {32, 64}) {
    const PlaneMaskTable table(side, 128);
    VisibilityMask mask(side);
    const int rings = 48, segments = 96;
    auto at = [&](int i, int j) {
      const double theta = std::numbers::pi * i / rings, phi = 2 * std::numbers::pi * j / segments;
      return glm::vec3(float(std::sin(theta) * std::cos(phi)),
                       float(std::sin(theta) * std::sin(phi)), float(2.0 + std::cos(theta)));
    };
    for (int i = 0; i < rings; ++i)
      for (int j = 0; j < segments; ++j) {
        rasterizeBlocker(at(i, j), at(i + 1, j), at(i + 1, j + 1), &table, mask);
        rasterizeBlocker(at(i, j), at(i + 1, j + 1), at(i, j + 1), &table, mask);
      }
    for (const bool downsample : {false, true}) {
      const TransferIntegrator integrator(side, {5, downsample});
      float t[25];
      integrator.diffuse(mask, TangentFrame{}, t);
      EXPECT_NEAR(t[0], want0, 0.02 * want0) << side << " " << downsample;
      EXPECT_NEAR(t[2], want2, 0.04 * want2) << side << " " << downsample;
      for (const int i : {1, 3, 4, 5, 7, 8}) EXPECT_NEAR(t[i], 0.0, 0.01) << i;
      if (!downsample) {
        const double e = std::abs(t[2] - want2) / want2;
        EXPECT_LT(e, previous) << side;
        previous = e;
      }
    }
  }
  EXPECT_LT(previous, 0.02);  // at 64 x 64
}

// The glossy lobe goes through the generic sum over samples; diffuse
// transfer at full resolution goes through the open sky minus the blocked
// pixels. A lobe of exponent zero is the constant 1 / (2 pi), so the two
// paths must agree on any mask.
TEST(Transfer, AGlossyLobeOfExponentZeroIsTheDiffuseTransferOverTwoPi) {
  std::mt19937 rng(5);
  for (const bool downsample : {true, false}) {
    const TransferIntegrator integrator(32, {5, downsample});
    for (const double density : {0.0, 0.3, 0.5, 0.9, 1.0}) {
      VisibilityMask mask(32);
      std::bernoulli_distribution blocked(density);
      for (int y = 0; y < 32; ++y)
        for (int x = 0; x < 32; ++x)
          if (maskPixelInDisk(32, x, y) && (density == 0.5 ? y < 16 : blocked(rng))) mask.set(x, y);
      const TangentFrame frame = TangentFrame::around(glm::normalize(glm::vec3(1, 2, 3)));
      float d[25], g[25];
      integrator.diffuse(mask, frame, d);
      integrator.glossy(mask, frame, glm::vec3(0, 1, 0), 0.0f, g);
      for (int i = 0; i < 25; ++i)
        EXPECT_NEAR(g[i], d[i] / (2 * std::numbers::pi), 2e-6)
            << i << " downsample " << downsample << " density " << density;
    }
  }
}

// The normalized Phong lobe about rLocal times the cosine, projected on the
// SH basis (world axes) by a fine latitude-longitude sum over the
// hemisphere: an oracle independent of the mask's disk pixels.
std::vector<double> glossyByQuadrature(const TangentFrame& frame, const glm::vec3& rLocal,
                                       double exponent) {
  std::vector<double> want(25, 0.0);
  const int steps = 600;
  float y[25];
  for (int i = 0; i < steps; ++i) {
    const double theta = (i + 0.5) * (std::numbers::pi / 2) / steps;
    for (int j = 0; j < 2 * steps; ++j) {
      const double phi = (j + 0.5) * std::numbers::pi / steps;
      const glm::vec3 local(float(std::sin(theta) * std::cos(phi)),
                            float(std::sin(theta) * std::sin(phi)), float(std::cos(theta)));
      const double cosine = local.z;
      const double lobe = (exponent + 1) / (2 * std::numbers::pi) *
                          std::pow(std::max(0.0, double(glm::dot(local, rLocal))), exponent);
      const double area =
          std::sin(theta) * (std::numbers::pi / 2 / steps) * (std::numbers::pi / steps);
      shEvaluate(frame.toWorld(local), 5, y);
      for (int k = 0; k < 25; ++k) want[size_t(k)] += lobe * cosine * area * y[k];
    }
  }
  return want;
}

// Glossy transfer of an open hemisphere against the quadrature: both mask
// resolutions (4x4 blocks and per pixel) agree with it for a broad lobe.
TEST(Transfer, GlossyTransferOfAnOpenHemisphereMatchesADirectQuadrature) {
  const TangentFrame frame = TangentFrame::around(glm::normalize(glm::vec3(0.3f, 1.0f, -0.2f)));
  const glm::vec3 rLocal = glm::normalize(glm::vec3(0.4f, -0.2f, 0.9f));
  const std::vector<double> want = glossyByQuadrature(frame, rLocal, 8.0);
  for (const bool downsample : {false, true}) {
    const TransferIntegrator integrator(64, {5, downsample});
    const VisibilityMask open(64);
    float got[25];
    integrator.glossy(open, frame, frame.toWorld(rLocal), 8.0f, got);
    EXPECT_LT(relativeL2(got, want, 25), downsample ? 0.05 : 0.03) << "downsample " << downsample;
  }
}

// The glossy Monte Carlo reference (self_shadow.h) against the same
// quadrature: a vertex with nothing above it (one triangle far below its
// tangent plane), and under a roof that hides its whole hemisphere.
TEST(Transfer, GlossyMonteCarloOfAnOpenVertexMatchesTheQuadratureAndARoofBlocksIt) {
  const glm::vec3 n = glm::normalize(glm::vec3(0.3f, 1.0f, -0.2f));
  const TangentFrame frame = TangentFrame::around(n);
  const glm::vec3 rLocal = glm::normalize(glm::vec3(0.4f, -0.2f, 0.9f));
  const std::vector<double> want = glossyByQuadrature(frame, rLocal, 8.0);
  const std::vector<glm::vec3> positions = {glm::vec3(0.0f), -10.0f * n + glm::vec3(1, 0, 0),
                                            -10.0f * n + glm::vec3(0, 0, 1),
                                            -10.0f * n + glm::vec3(-1, 0, -1)};
  const std::vector<glm::vec3> normals(4, n), reflected(4, frame.toWorld(rLocal));
  const std::vector<uint8_t> first = {1, 0, 0, 0};
  std::vector<float> got;
  monteCarloGlossyTransfer(positions, normals, {glm::uvec3(1, 2, 3)}, reflected, 8.0f, 65536, 5,
                           got, 0, &first);
  EXPECT_LT(relativeL2(got.data(), want, 25), 0.02);
  for (size_t i = 25; i < got.size(); ++i) EXPECT_EQ(got[i], 0.0f);  // not traced
  // A roof 1 m above, 1 km wide.
  const glm::vec3 up = n, t = frame.t, b = frame.b;
  const std::vector<glm::vec3> roofed = {glm::vec3(0.0f), up + 1000.0f * (t + b),
                                         up + 1000.0f * (b - t), up - 1000.0f * b * 2.0f};
  monteCarloGlossyTransfer(roofed, normals, {glm::uvec3(1, 2, 3)}, reflected, 8.0f, 4096, 5, got, 0,
                           &first);
  double sum = 0.0;
  for (int i = 0; i < 25; ++i) sum += std::abs(got[size_t(i)]);
  EXPECT_LT(sum, 1e-3);
}

// Why avatars integrate glossy lobes per pixel (AvatarShaderOptions): on the
// shader's 32 x 32 masks, per-pixel sums stay within 2% of the quadrature for
// every exponent up to the client's limit of 256 (beyond it the lobe is
// narrower than a pixel), while 4x4 blocks (about 50 samples) lose it.
TEST(Transfer, ASharpGlossyLobeNeedsEveryPixelOfTheMask) {
  const TangentFrame frame = TangentFrame::around(glm::normalize(glm::vec3(-0.5f, 0.8f, 0.1f)));
  const glm::vec3 rLocal = glm::normalize(glm::vec3(-0.3f, 0.5f, 0.8f));
  const TransferIntegrator perPixel(32, {5, false}), blocks(32, {5, true});
  const VisibilityMask open(32);
  for (const float exponent : {16.0f, 64.0f, 256.0f}) {
    const std::vector<double> want = glossyByQuadrature(frame, rLocal, exponent);
    float got[25];
    perPixel.glossy(open, frame, frame.toWorld(rLocal), exponent, got);
    EXPECT_LT(relativeL2(got, want, 25), 0.02) << "exponent " << exponent;
    if (exponent >= 256.0f) {
      blocks.glossy(open, frame, frame.toWorld(rLocal), exponent, got);
      EXPECT_GT(relativeL2(got, want, 25), 0.1) << "exponent " << exponent;
    }
  }
}

}  // namespace
}  // namespace vistream
