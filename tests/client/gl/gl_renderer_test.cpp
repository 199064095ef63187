// The OpenGL near field, checked pixel by pixel on Mesa's software OpenGL
// under Xvfb (ctest starts this binary through xvfb-run). Oracles: the
// symmetry of a centred camera (x = 0 and y = 0 project onto the middle
// column and row), the bytes the CPU computed for each triangle, and the
// independent software rasterizer.
#include "client/gl/gl_renderer.h"

#include <epoxy/gl.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "client/gl/gl_window.h"
#include "client/render/soft_raster.h"
#include "common/core/error.h"

namespace vistream {
namespace {

// Odd sizes, so rows are not a multiple of 4 bytes and the image centre lies
// on pixel centres.
constexpr int kWidth = 321, kHeight = 241;

std::string show(glm::u8vec3 c) {
  std::ostringstream os;
  os << '(' << int(c.r) << ", " << int(c.g) << ", " << int(c.b) << ')';
  return os.str();
}

void addTriangle(RenderGeometry& g, glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::u8vec3 colour) {
  FlatTriangles& t = g.triangles;
  t.positions.insert(t.positions.end(), {a, b, c});
  t.faceIds.push_back(uint32_t(t.faceIds.size()));
  t.objectIds.push_back(0);
  t.degenerate.push_back(isDegenerateTriangle(a, b, c) ? 1 : 0);
  g.lighting.appendFlat(colour);
}

// An axis-aligned rectangle at depth z (two triangles).
void addRectangle(RenderGeometry& g, float x0, float x1, float y0, float y1, float z,
                  glm::u8vec3 colour) {
  addTriangle(g, {x0, y0, z}, {x1, y0, z}, {x1, y1, z}, colour);
  addTriangle(g, {x0, y0, z}, {x1, y1, z}, {x0, y1, z}, colour);
}

std::vector<uint32_t> allTriangles(const RenderGeometry& g) {
  std::vector<uint32_t> all(g.size());
  for (uint32_t t = 0; t < all.size(); ++t) all[t] = t;
  return all;
}

class GlFrame : public ::testing::Test {
 protected:
  void SetUp() override {
    try {
      window_ = std::make_unique<GlWindow>(
          GlWindowOptions{kWidth, kHeight, "gl_renderer_test", false, false});
    } catch (const InputError& e) {
      FAIL()
          << "cannot open an OpenGL window: " << e.what()
          << "\nThis test needs a display: run it through ctest, which starts it under xvfb-run.";
    }
    renderer_ = std::make_unique<GlRenderer>();
    camera_.width = window_->framebufferWidth();
    camera_.height = window_->framebufferHeight();
    ASSERT_EQ(camera_.width, kWidth);
    ASSERT_EQ(camera_.height, kHeight);
  }

  ImageRgb8 render(const RenderGeometry& g, const ImageRgb8& farField,
                   std::span<const uint32_t> near, std::span<const HudLine> hud = {}) {
    renderer_->upload(g);
    renderer_->draw(camera_, farField, near, std::numeric_limits<float>::infinity(), hud);
    ImageRgb8 frame = renderer_->readBack(camera_.width, camera_.height);
    EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
    return frame;
  }

  std::unique_ptr<GlWindow> window_;
  std::unique_ptr<GlRenderer> renderer_;
  Camera camera_;  // at the origin, looking along -Z, upright
};

// Counts the pixels where `want` (nullopt: do not check) differs from the
// frame and describes the first one.
template <class Want>
std::pair<int, std::string> mismatches(const ImageRgb8& frame, Want&& want) {
  int count = 0;
  std::string first;
  for (int y = 0; y < frame.height; ++y)
    for (int x = 0; x < frame.width; ++x) {
      const std::optional<glm::u8vec3> w = want(x, y);
      if (!w || *w == frame.at(x, y)) continue;
      if (count++ == 0)
        first = "pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") is " +
                show(frame.at(x, y)) + ", want " + show(*w);
    }
  return {count, first};
}

TEST_F(GlFrame, ShowsEachTrianglesCpuColourAndTheFarFieldElsewhereWithTheNearerQuadInFront) {
  RenderGeometry g;
  // The far quad covers the upper half; the near quad the left half. Far is
  // listed last, so without a depth test it would cover the near one.
  addRectangle(g, -10.0f, 0.0f, -10.0f, 10.0f, -2.0f, {0, 0, 0});
  addRectangle(g, -10.0f, 10.0f, 0.0f, 10.0f, -4.0f, {0, 0, 0});
  recolour(g, [](size_t t) {
    return t < 2 ? glm::vec3(0.8f, 0.1f, 0.1f) : glm::vec3(0.1f, 0.7f, 0.2f);
  });
  const glm::u8vec3 nearColour = g.lighting.meanColour(0), farColour = g.lighting.meanColour(2);
  ASSERT_NE(nearColour, farColour);
  ASSERT_EQ(g.lighting.meanColour(1), nearColour);
  ASSERT_EQ(g.lighting.meanColour(3), farColour);

  ImageRgb8 farField(kWidth, kHeight);
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x)
      farField.set(x, y, {uint8_t(x), uint8_t(y), uint8_t(77 + (x ^ y) % 64)});

  const std::vector<uint32_t> near = allTriangles(g);
  const ImageRgb8 frame = render(g, farField, near);
  // x = 0 and y = 0 project onto the image centre (160.5, 120.5); pixels
  // within 2 px of those lines are edge pixels and not checked.
  const auto [count, first] = mismatches(frame, [&](int x, int y) -> std::optional<glm::u8vec3> {
    const float dx = float(x) + 0.5f - 0.5f * kWidth, dy = float(y) + 0.5f - 0.5f * kHeight;
    if (std::abs(dx) < 2.0f || std::abs(dy) < 2.0f) return std::nullopt;
    if (dx < 0.0f) return nearColour;
    if (dy < 0.0f) return farColour;
    return farField.at(x, y);
  });
  EXPECT_EQ(count, 0) << first;
}

TEST_F(GlFrame, ReadBackPutsRowZeroAtTheTop) {
  RenderGeometry g;
  // Above the eye's height: only the upper half of an upright camera sees it.
  addTriangle(g, {-50.0f, 0.05f, -5.0f}, {50.0f, 0.05f, -5.0f}, {0.0f, 50.0f, -5.0f},
              {250, 200, 10});
  const glm::u8vec3 background{20, 30, 40};
  const std::vector<uint32_t> near = allTriangles(g);
  const ImageRgb8 frame = render(g, ImageRgb8(kWidth, kHeight, background), near);
  int upper = 0, lower = 0;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x)
      if (frame.at(x, y) == g.lighting.meanColour(0)) ++(y < kHeight / 2 ? upper : lower);
  EXPECT_GT(upper, kWidth * kHeight / 4);
  EXPECT_EQ(lower, 0);
  EXPECT_EQ(frame.at(kWidth / 2, 0), g.lighting.meanColour(0));
  EXPECT_EQ(frame.at(kWidth / 2, kHeight - 1), background);
}

TEST_F(GlFrame, ClearsToBlackWhenTheFarFieldImageHasTheWrongSize) {
  RenderGeometry g;
  addTriangle(g, {0.0f, 0.0f, -5.0f}, {1.0f, 0.0f, -5.0f}, {0.0f, 1.0f, -5.0f}, {9, 9, 9});
  const std::vector<uint32_t> none;
  const ImageRgb8 frame = render(g, ImageRgb8(kWidth - 1, kHeight, {200, 100, 50}), none);
  const auto [count, first] =
      mismatches(frame, [](int, int) { return std::optional(glm::u8vec3(0, 0, 0)); });
  EXPECT_EQ(count, 0) << first;
}

// ~200 random, overlapping and interpenetrating triangles in front of the
// camera, three in four of them listed.
struct RandomScene {
  RenderGeometry g;
  std::vector<uint32_t> near;
  glm::u8vec3 background{255, 0, 255};  // no triangle has red above 200
};

RandomScene randomScene(const Camera& camera) {
  RandomScene s;
  std::mt19937 rng(20240611u);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f), depth(3.0f, 30.0f), size(0.05f, 0.3f);
  std::uniform_int_distribution<int> red(0, 200), byte(0, 255);
  const float tanX = std::tan(camera.halfHfov()),
              tanY = std::tan(0.5f * glm::radians(camera.vfovDeg));
  for (int t = 0; t < 200; ++t) {
    const float d = depth(rng);
    const glm::vec3 centre(1.1f * d * tanX * unit(rng), 1.1f * d * tanY * unit(rng), -d);
    const float r = d * size(rng);
    auto corner = [&] { return centre + r * glm::vec3(unit(rng), unit(rng), unit(rng)); };
    const glm::vec3 a = corner(), b = corner(), c = corner();
    addTriangle(s.g, a, b, c, {uint8_t(red(rng)), uint8_t(byte(rng)), uint8_t(byte(rng))});
    if (t % 4 != 0) s.near.push_back(uint32_t(t));
  }
  // Colours that vary across each triangle (a grid of level 1 to 4 of random
  // colours) and haze, so the shader's lookup and fading are what is compared.
  s.g.lighting = LightingGrid{};
  std::uniform_int_distribution<uint32_t> level(1, 4);
  for (int t = 0; t < 200; ++t) {
    const uint32_t n = level(rng);
    std::vector<glm::u8vec3> points(LightingGrid::pointsOf(n));
    for (auto& p : points) p = {uint8_t(red(rng)), uint8_t(byte(rng)), uint8_t(byte(rng))};
    s.g.lighting.append(n, points.data(), points.size());
  }
  s.g.haze = Haze{glm::vec3(40.0f, 60.0f, 80.0f), 25.0f};
  return s;
}

TEST_F(GlFrame, MatchesTheSoftwareRasterizerExceptOnAFewEdgePixels) {
  const RandomScene s = randomScene(camera_);
  const ImageRgb8 farField(kWidth, kHeight, s.background);
  const ImageRgb8 frame = render(s.g, farField, s.near);

  SoftwareRasterizer soft;
  IdBuffer ids;
  soft.draw(camera_, s.g.triangles, s.near, ids);
  const Camera::PixelRays rays = camera_.pixelRays();
  int drawn = 0;
  const auto [count, first] = mismatches(frame, [&](int x, int y) {
    const uint32_t id = ids.at(x, y);
    drawn += id != kNoTriangle;
    return std::optional(
        id == kNoTriangle
            ? s.background
            : s.g.colourAlong(id, camera_.eye, rays.at(float(x) + 0.5f, float(y) + 0.5f)));
  });
  RecordProperty("differingPixels", count);
  EXPECT_GT(drawn, kWidth * kHeight / 4) << "the scene should cover much of the frame";
  EXPECT_LE(count, kWidth * kHeight / 200) << count << " pixels differ; first: " << first;
}

TEST_F(GlFrame, DrawsEveryPixelTheInsetCoverageCallsCovered) {
  const RandomScene s = randomScene(camera_);
  const ImageRgb8 frame = render(s.g, ImageRgb8(kWidth, kHeight, s.background), s.near);

  SoftwareRasterizer soft;
  std::vector<uint8_t> covered;
  soft.coverage(camera_, s.g.triangles, s.near, 0.1f, covered);
  int coveredCount = 0;
  const auto [count, first] = mismatches(frame, [&](int x, int y) -> std::optional<glm::u8vec3> {
    if (covered[size_t(y) * kWidth + size_t(x)] != kCovered) return std::nullopt;
    ++coveredCount;
    if (frame.at(x, y) != s.background) return std::nullopt;
    return glm::u8vec3(0, 0, 0);  // any triangle colour; reported as "want (0, 0, 0)"
  });
  EXPECT_GT(coveredCount, kWidth * kHeight / 4);
  EXPECT_EQ(count, 0) << count << " covered pixels show the background; first: " << first;
}

TEST_F(GlFrame, HudDarkensABoxAtTheTopLeftWritesWhiteInItAndLeavesTheRestAlone) {
  const glm::u8vec3 background{200, 150, 100};
  const RenderGeometry g;
  const std::vector<uint32_t> none;
  const std::vector<HudLine> hud = {{"frame 12"}, {"faces 3456"}};
  const ImageRgb8 frame = render(g, ImageRgb8(kWidth, kHeight, background), none, hud);

  // The box is translucent black: 0.6 black over the background, +-1 for rounding.
  const glm::u8vec3 corner = frame.at(5, 5);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(corner[i], 0.4 * background[i], 1.0) << "channel " << i;
  int white = 0;
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < 160; ++x) white += frame.at(x, y) == glm::u8vec3(255, 255, 255);
  EXPECT_GT(white, 50);
  const auto [count, first] = mismatches(frame, [&](int x, int y) -> std::optional<glm::u8vec3> {
    if (x < kWidth / 2 && y < kHeight / 2) return std::nullopt;
    return background;
  });
  EXPECT_EQ(count, 0) << first;
}

// The HUD vistream-client shows, with numbers as wide as a big scene makes them.
std::vector<HudLine> clientHud() {
  return {{"frame 1234.5 ms (pipeline 1234.5 ms)  near 12345678 triangles  d = 150 m"},
          {"pixels: polygon 307200  horizon 307200  cache 307200  ray hit 307200  ray miss 307200"},
          {"faces held 1234567  received 1234.5 MB  far field off  horizon off  cache off"}};
}

std::string withoutSpaces(const std::string& text) {
  std::string out;
  for (char c : text)
    if (c != ' ') out += c;
  return out;
}

TEST(HudLayout, WrapsTheClientHudToTheDefaultWindowWithoutLosingText) {
  const std::vector<HudLine> hud = clientHud();
  const HudLayout layout = layoutHud(hud, 640, 480);
  // The box lies inside the window and covers at most half of its height.
  EXPECT_GE(layout.boxLo.x, 0.0f);
  EXPECT_LE(layout.boxHi.x, 640.0f);
  EXPECT_LE(layout.boxHi.y, 240.0f);
  EXPECT_EQ(layout.scale, 2.0f);
  // Every character of the input is still there, in order.
  std::string in, out;
  for (const HudLine& l : hud) in += withoutSpaces(l.text);
  for (const std::string& l : layout.lines) out += withoutSpaces(l);
  EXPECT_EQ(out, in);
  EXPECT_GT(layout.lines.size(), hud.size()) << "these lines are wider than 640 px at 2x";
}

TEST(HudLayout, KeepsShortLinesWholeAndFallsBackToSingleSizeInATinyWindow) {
  const std::vector<HudLine> hud = {{"frame 12"}, {"faces 3456"}};
  const HudLayout wide = layoutHud(hud, 2000, 1000);
  EXPECT_EQ(wide.scale, 2.0f);
  EXPECT_EQ(wide.lines, (std::vector<std::string>{"frame 12", "faces 3456"}));
  // 60 x 40: at 2x "faces 3456" alone is wider than the window.
  const HudLayout tiny = layoutHud(hud, 60, 40);
  EXPECT_EQ(tiny.scale, 1.0f);
}

// Draws the client's HUD in a 640 x 480 window (vistream-client's default)
// over a uniform background: the box ends inside the window, so the last
// columns keep the background on every row. VISTREAM_HUD_PNG=FILE writes
// the frame to look at.
TEST(GlHud, FitsTheDefaultWindowOfTheClient) {
  std::unique_ptr<GlWindow> window;
  try {
    window = std::make_unique<GlWindow>(GlWindowOptions{640, 480, "hud_test", false, false});
  } catch (const InputError& e) {
    FAIL() << "cannot open an OpenGL window: " << e.what();
  }
  GlRenderer renderer;
  Camera camera;
  camera.width = window->framebufferWidth();
  camera.height = window->framebufferHeight();
  ASSERT_EQ(camera.width, 640);
  const glm::u8vec3 background{200, 150, 100};
  const RenderGeometry g;
  renderer.upload(g);
  const std::vector<HudLine> hud = clientHud();
  renderer.draw(camera, ImageRgb8(640, 480, background), {}, std::numeric_limits<float>::infinity(),
                hud);
  const ImageRgb8 frame = renderer.readBack(640, 480);
  if (const char* png = std::getenv("VISTREAM_HUD_PNG")) writePng(frame, png);
  int white = 0;
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x) white += frame.at(x, y) == glm::u8vec3(255, 255, 255);
  EXPECT_GT(white, 500);
  const auto [count, first] = mismatches(frame, [&](int x, int) -> std::optional<glm::u8vec3> {
    if (x < 640 - 2) return std::nullopt;
    return background;
  });
  EXPECT_EQ(count, 0) << "the HUD reaches the right edge; first: " << first;
}

// Runs in a child process (gtest re-executes this binary), which drops the
// display it inherited from xvfb-run.
TEST(GlWindowDeathTest, ThrowsInputErrorNamingTheDisplayWhenThereIsNone) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        unsetenv("DISPLAY");
        unsetenv("WAYLAND_DISPLAY");
        try {
          GlWindow window(GlWindowOptions{64, 64, "no display", false, false});
        } catch (const InputError& e) {
          std::fprintf(stderr, "InputError: %s\n", e.what());
          std::exit(0);
        }
        std::exit(1);
      },
      ::testing::ExitedWithCode(0), "InputError: .*display");
}

}  // namespace
}  // namespace vistream
