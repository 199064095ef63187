// The OpenGL path of the client against its headless path: the same pose
// through FrameRenderer::renderFarField + GlRenderer (OpenGL near field,
// opacity buffer with an inset) and through FrameRenderer::render (software
// near field) gives the same frame, up to pixels on triangle edges.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <tuple>

#include "client/app/walkthrough.h"
#include "client/farfield/pipeline.h"
#include "client/gl/gl_renderer.h"
#include "client/gl/gl_window.h"
#include "common/core/error.h"
#include "common/generate/generate.h"
#include "common/generate/path.h"
#include "tests/common/support/box_scenes.h"
#include "tests/common/support/run_tool.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

TEST(GlPipeline, AnOpenGLFrameMatchesTheHeadlessFrameOfTheSamePose) {
  constexpr int kW = 320, kH = 240;
  std::unique_ptr<GlWindow> window;
  try {
    window = std::make_unique<GlWindow>(GlWindowOptions{kW, kH, "gl_pipeline_test", false, false});
  } catch (const InputError& e) {
    FAIL() << "cannot open an OpenGL window: " << e.what()
           << " (run through ctest, which uses xvfb-run)";
  }
  const Scene scene = toScene(generate("city1"));
  const RenderGeometry g = renderGeometryFromScene(scene);
  PathOptions po;
  po.frames = 12;
  po.speed = 3.0;
  const auto cams = camerasFromPath(generatePath(scene, po), scene.origin, kW, kH, 60.0f);
  PipelineOptions o;
  o.polygonBudget = 0;  // split at d although city1 is small enough to draw whole
  o.nearDistance = 60.0f;
  for (RenderMode mode : {RenderMode::Pipeline, RenderMode::GeometryAll}) {
    o.mode = mode;
    FrameRenderer headless(g, o), forGl(g, o);
    GlRenderer gl;
    gl.upload(g);
    ImageRgb8 soft, farImage;
    std::vector<uint32_t> near;
    size_t farPixels = 0;
    for (size_t i = 0; i < cams.size(); i += 3) {
      headless.render(cams[i], soft);
      const FrameReport r = forGl.renderFarField(cams[i], farImage, near);
      farPixels += r.pixels.rayHit + r.pixels.rayMiss + r.pixels.cache + r.pixels.horizon;
      gl.draw(cams[i], farImage, near, forGl.polygonDistance());
      const ImageRgb8 frame = gl.readBack(kW, kH);
      const ImageDifference d = compareImages(frame, soft, /*tolerance=*/1);
      EXPECT_LT(d.differingFraction, 0.005) << renderModeName(mode) << " frame " << i;
      EXPECT_EQ(d.interiorDiffering, 0u) << renderModeName(mode) << " frame " << i;
    }
    if (mode == RenderMode::Pipeline) {
      EXPECT_GT(farPixels, 0u) << "the far field took part";
    }
  }
}

// vistream-client in a window (this binary runs under xvfb-run, and so does
// the child) renders a path to PNG frames that match its headless frames.
TEST(GlPipeline, TheWindowedClientRendersAPathLikeTheHeadlessOne) {
  vistream::testing::TempDir dir;
  const std::string path =
      dir.write("walk.csv", "t,x,y,z,yaw_deg,pitch_deg\n0,0,1.7,0,0,0\n0.1,0,1.7,-0.1,20,0\n")
          .string();
  const std::string common =
      "--scene city1 --path " + path + " --size 200x150 --near-distance 50 --polygon-budget 0";
  const auto window = vistream::testing::runTool("vistream-client",
                                                 common + " --out " + (dir.path() / "gl").string());
  ASSERT_EQ(window.status, 0) << window.err;
  const auto headless = vistream::testing::runTool(
      "vistream-client", common + " --headless --out " + (dir.path() / "soft").string());
  ASSERT_EQ(headless.status, 0) << headless.err;
  for (const char* name : {"frame_00000.png", "frame_00001.png"}) {
    const ImageDifference d =
        compareImages(readPng(dir.path() / "gl" / name), readPng(dir.path() / "soft" / name),
                      /*tolerance=*/1);
    EXPECT_LT(d.differingFraction, 0.005) << name;
    EXPECT_EQ(d.interiorDiffering, 0u) << name;
  }
}

// Avatars (simulated users beside the path) look the same in a window as
// headless: OpenGL draws them from the same corner colours with the same
// depth test, so only edge pixels may differ.
TEST(GlPipeline, TheWindowedClientDrawsAvatarsLikeTheHeadlessOne) {
  vistream::testing::TempDir dir;
  const std::string common =
      "--scene city1 --path auto --frames 40 --avatars 4 --size 200x150 --polygon-budget 0 "
      "--near-distance 60";
  const auto window = vistream::testing::runTool("vistream-client",
                                                 common + " --out " + (dir.path() / "gl").string());
  ASSERT_EQ(window.status, 0) << window.err;
  const auto headless = vistream::testing::runTool(
      "vistream-client", common + " --headless --json --out " + (dir.path() / "soft").string());
  ASSERT_EQ(headless.status, 0) << headless.err;
  const nlohmann::json j = nlohmann::json::parse(headless.out);
  size_t withAvatars = 0;
  for (const auto& f : j["per_frame"]) {
    const size_t avatarPixels = f["avatars"]["pixels"].get<size_t>();
    if (avatarPixels < 100) continue;
    ++withAvatars;
    const std::string name = fmt::format("frame_{:05d}.png", f["frame"].get<size_t>());
    const ImageDifference d =
        compareImages(readPng(dir.path() / "gl" / name), readPng(dir.path() / "soft" / name),
                      /*tolerance=*/1);
    EXPECT_LT(d.differingFraction, 0.005) << name << " with " << avatarPixels << " avatar pixels";
    EXPECT_EQ(d.interiorDiffering, 0u) << name;
  }
  EXPECT_GT(withAvatars, 5u) << "frames that show avatars";
}

// A synthetic impostor: a wall of points 200 m ahead, each with a texture
// of random colours (every fifth one a single colour), so that the colour a
// pixel shows depends on the eye's sampling-plane coordinates.
std::shared_ptr<ImpostorSet> wallOfPoints() {
  Impostor imp;
  imp.cell = Box3f({-5.0f, 0.5f, -5.0f}, {5.0f, 4.0f, 5.0f});
  imp.box = Box3f({-80.0f, 0.0f, -201.0f}, {80.0f, 50.0f, -199.0f});
  imp.plane.origin = {-30.0f, -5.0f, -10.0f};
  imp.plane.uAxis = {60.0f, 0.0f, 0.0f};
  imp.plane.vAxis = {0.0f, 30.0f, 0.0f};
  imp.plane.normal = {0.0f, 0.0f, -1.0f};
  std::mt19937 random(7);
  std::uniform_int_distribution<int> level(0, 255);
  std::vector<glm::u8vec3> texels(imp.textureTexels());
  int k = 0;
  // Points half a pixel apart up to 25 m, then 1.3 pixels apart: a point
  // covers only the pixel centres within its splat's radius, and the
  // sparse part shows the gaps between them.
  for (float y = 0.0f; y <= 50.0f; y += y < 25.0f ? 0.5f : 1.25f)
    for (float x = -80.0f; x <= 80.0f; x += y < 25.0f ? 0.5f : 1.25f, ++k) {
      for (glm::u8vec3& t : texels) t = glm::u8vec3(level(random), level(random), level(random));
      // A little depth relief, so that points also compete among themselves.
      imp.appendPoint({x, y, -200.0f + 0.5f * std::sin(0.7f * x + 0.3f * y)}, texels.data(),
                      k % 5 == 0);
    }
  auto set = std::make_shared<ImpostorSet>();
  set->cell = imp.cell;
  set->impostors.push_back(std::make_shared<const Impostor>(std::move(imp)));
  set->expected = 1;
  return set;
}

// The impostors' points drawn by the OpenGL point shader (GpuImpostors)
// give the frame the software splat gives: same points, same depth rule
// against the held far field (a tower in front hides part of the wall), same
// colours seen from the eye.
TEST(GlPipeline, ThePointShaderDrawsImpostorsAsTheSoftwareSplatterDoes) {
  constexpr int kW = 320, kH = 240;
  std::unique_ptr<GlWindow> window;
  try {
    window = std::make_unique<GlWindow>(GlWindowOptions{kW, kH, "gl_pipeline_test", false, false});
  } catch (const InputError& e) {
    FAIL() << "cannot open an OpenGL window: " << e.what();
  }
  Scene scene;
  scene.name = "impostor wall";
  testing::addBox(scene, "ground", {-300.0f, -1.0f, -300.0f}, {300.0f, 0.0f, 60.0f});
  testing::addBox(scene, "tower", {-20.0f, 0.0f, -120.0f}, {5.0f, 30.0f, -110.0f});
  testing::addBox(scene, "near", {6.0f, 0.0f, -30.0f}, {9.0f, 4.0f, -27.0f});
  finalizeScene(scene);
  const RenderGeometry g = renderGeometryFromScene(scene);
  const std::shared_ptr<ImpostorSet> set = wallOfPoints();
  PipelineOptions o;
  o.polygonBudget = 0;
  o.nearDistance = 50.0f;
  FrameRenderer headless(g, o), forGl(g, o);
  headless.setImpostors(set);
  forGl.setImpostors(set);
  GlRenderer gl;
  gl.upload(g);
  size_t impostorPixels = 0;
  for (const auto& [yaw, pitch, x] : {std::tuple{0.0f, 3.0f, 0.0f},
                                      {15.0f, 8.0f, -3.0f},
                                      {-25.0f, 1.0f, 4.0f},
                                      {40.0f, 5.0f, 2.0f}}) {
    Camera c;
    c.width = kW;
    c.height = kH;
    c.eye = {x, 2.0f, 1.0f};
    c.yawDeg = yaw;
    c.pitchDeg = pitch;
    ImageRgb8 soft, farImage;
    const FrameReport sr = headless.render(c, soft);
    impostorPixels += sr.pixels.impostor;
    std::vector<uint32_t> near;
    GpuImpostors gpu;
    const FrameReport gr = forGl.renderFarField(c, farImage, near, &gpu);
    EXPECT_TRUE(gr.impostorsRan) << gr.impostorsWhy;
    EXPECT_EQ(gpu.impostors.size(), 1u);
    EXPECT_EQ(gr.pixels.impostor, 0u) << "the GPU draws the points";
    gl.draw(c, farImage, near, forGl.polygonDistance(), {}, &gpu);
    const ImageRgb8 frame = gl.readBack(kW, kH);
    const ImageDifference d = compareImages(frame, soft, /*tolerance=*/1);
    EXPECT_LT(d.differingFraction, 0.005)
        << "yaw " << yaw << ": " << sr.pixels.impostor << " impostor pixels";
  }
  EXPECT_GT(impostorPixels, 15'000u) << "the wall took part";
}

}  // namespace
}  // namespace vistream
