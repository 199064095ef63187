// vistream-client: the thin client. Renders the near field as polygons and
// the far field through the thesis's pixel pipeline (horizon tracing,
// panoramic image cache, ray casting), from a local scene (--scene) or from
// what a vistream-server streams (--host/--port); in a window (OpenGL) or
// headless (software near field, PNG frames, statistics).
#include "client/cmd/client_commands.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "client/app/walkthrough.h"
#include "client/avatar/avatar_view.h"
#include "client/avatar/crowd.h"
#include "client/farfield/pipeline.h"
#include "client/gl/gl_renderer.h"
#include "client/gl/gl_window.h"
#include "client/net/stream_client.h"
#include "client/render/render_geometry.h"
#include "client/render/streamed_geometry.h"
#include "common/cmd/cli.h"
#include "common/core/error.h"
#include "common/core/log.h"
#include "common/core/progress.h"
#include "common/core/timer.h"
#include "common/generate/generate.h"
#include "common/generate/path.h"
#include "common/generate/scene_spec.h"
#include "common/light/environment_light.h"
#include "common/scene/scene_loader.h"
#include "common/world/static_world.h"

namespace vistream {
namespace {

struct Args {
  std::string scene, host, pathFile, size = "640x480", outDir, mode = "pipeline", logLevel = "warn",
                                     token, sheetFile;
  SceneLimits sceneLimits;
  std::filesystem::path lightingCache;  // empty: no cache
  GroundChoice ground;                  // for --path auto
  uint16_t port = 7070;
  bool headless = false, json = false, noCache = false, compare = false;
  std::string intake = "incremental";
  size_t frames = 0;
  float vfov = 60.0f;
  float nearDistance = 0.0f;
  float streamRadius = 0.0f;
  size_t pixelBudget = 2'000;
  size_t polygonBudget = 500'000;
  float maxStalePixels = 2.0f;
  float horizonCell = 8.0f;
  int horizonSubsample = 4;
  double pathSpeed = 1.0;
  double waitS = 20.0;
  size_t avatars = 0;         // simulated users walking local paths
  bool noAvatars = false;     // connected: do not ask for or draw other users
  bool noReconnect = false;   // connected: a lost server ends the walk
  bool realtime = false;      // headless: frames at the path's clock, not as fast as possible
  std::string avatarModel;    // skinned glTF; empty: the default
  float avatarHeight = 1.2f;  // metres
  float avatarGloss = 0.0f;   // Phong exponent of the avatars' glossy term; 0: diffuse only
};

RenderMode parseMode(const std::string& m) {
  if (m == "pipeline") return RenderMode::Pipeline;
  if (m == "raycast-all") return RenderMode::RaycastAll;
  if (m == "geometry-all") return RenderMode::GeometryAll;
  if (m == "impostor-off") return RenderMode::ImpostorOff;
  throwInputError("--mode {}: expected pipeline, raycast-all, geometry-all or impostor-off", m);
}

std::string frameName(size_t i) {
  return fmt::format("frame_{:05d}.png", i);
}

// The path to walk: a file, or "auto" (generated through the scene's free space).
std::vector<PathSample> loadPath(const Args& a, const Scene* scene, size_t frames) {
  if (a.pathFile != "auto") return readPath(a.pathFile);
  if (!scene)
    throwInputError(
        "--path auto needs --scene (the path is generated through its free space; with --host, "
        "give the scene the server serves)");
  PathOptions po;
  po.frames = frames ? frames : 300;
  po.speed = a.pathSpeed;
  po.ground = a.ground;
  return generatePath(*scene, po);
}

PipelineOptions pipelineOptions(const Args& a, const Scene* scene, RenderMode mode) {
  PipelineOptions o;
  o.mode = mode;
  o.nearDistance = a.nearDistance > 0.0f ? a.nearDistance
                                         : (scene ? scene->environment.nearFieldRadius : 150.0f);
  o.pixelBudget = a.pixelBudget;
  o.polygonBudget = a.polygonBudget;
  o.cache = !a.noCache;
  o.maxStalePixels = a.maxStalePixels;
  o.horizonCellSize = a.horizonCell;
  o.horizonSubsampleMoving = a.horizonSubsample;
  if (scene) {
    o.horizonAllowed = scene->environment.sky != SkyMode::None;
    const Box3f b = scene->bounds();
    o.farFieldAllowed = !b.empty() && glm::length(b.extent()) > o.nearDistance;
  }
  return o;
}

// --sheet FILE: four frames evenly spaced along the walk, side by side in one
// row; a FILE already holding a sheet of the same width gets the row below
// its own, so several runs (scenes) make one contact sheet.
class ContactSheetRow {
 public:
  ContactSheetRow(std::string file, size_t frames) : file_(std::move(file)) {
    if (file_.empty() || frames == 0) return;
    for (size_t k = 0; k < kTiles; ++k)
      picks_.push_back(frames == 1 ? 0 : k * (frames - 1) / (kTiles - 1));
  }
  void offer(size_t frame, const ImageRgb8& image) {
    if (std::find(picks_.begin(), picks_.end(), frame) != picks_.end() && tiles_.size() < kTiles)
      tiles_.push_back(image);
  }
  void write() const {
    if (file_.empty() || tiles_.empty()) return;
    ImageRgb8 sheet = contactSheet(tiles_, int(kTiles));
    std::error_code ec;
    if (std::filesystem::exists(file_, ec)) {
      try {
        const ImageRgb8 before = readPng(file_);
        if (before.width == sheet.width) sheet = stackImages(before, sheet);
      } catch (const InputError&) {
        // Not a sheet of ours: replaced.
      }
    }
    writePng(sheet, file_);
    spdlog::info("contact sheet row written to {}", file_);
  }

 private:
  static constexpr size_t kTiles = 4;
  std::string file_;
  std::vector<size_t> picks_;
  std::vector<ImageRgb8> tiles_;
};

// What a connected walk received and how long it waited for geometry.
struct ConnectionFigures {
  uint64_t bytesReceived = 0;
  double waitMs = 0.0;  // in waitForCell: the first view cell and each frame's
  size_t waits = 0;
  size_t timeouts = 0;  // waits that ended without the cell complete
  bool impostorsOffered = false;
  StreamClient::ImpostorFigures impostors;
};

void printSummary(const Args& a, const std::vector<FrameRecord>& records, const PipelineOptions& o,
                  glm::ivec2 size, const ConnectionFigures* connection = nullptr) {
  if (a.json) {
    nlohmann::json j = walkthroughJson(records, o, size.x, size.y);
    if (connection)
      j["connection"] = {{"bytes_received", connection->bytesReceived},
                         {"wait_for_geometry_ms", connection->waitMs},
                         {"waits", connection->waits},
                         {"wait_timeouts", connection->timeouts},
                         {"impostors_offered", connection->impostorsOffered},
                         {"impostor_cells", connection->impostors.cells},
                         {"impostors", connection->impostors.impostors},
                         {"impostor_bytes", connection->impostors.bytes}};
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::printf("%s", walkthroughTable(records, o).c_str());
    if (connection)
      std::printf("received %.2f MB; waited %.0f ms for geometry in %zu waits (%zu timed out)\n",
                  double(connection->bytesReceived) / 1e6, connection->waitMs, connection->waits,
                  connection->timeouts);
    if (connection && connection->impostorsOffered)
      std::printf("impostors: %zu of %zu cells, %.2f MB\n", connection->impostors.impostors,
                  connection->impostors.cells, double(connection->impostors.bytes) / 1e6);
    if (!a.outDir.empty())
      std::printf("\nframes written to %s/frame_00000.png ...\n", a.outDir.c_str());
  }
}

// The geometry a renderer draws, and the renderers built over it. A local
// scene is built once. A connected client takes up what the server sent or
// evicted as it comes (StreamedGeometry, FrameRenderer::update): renderers
// are built again only when dead slots outnumber live ones (compaction) or
// the near-field grid outgrows its limit.
struct LiveGeometry {
  static constexpr size_t kMaxRayBatches = 256;
  std::unique_ptr<RenderGeometry> local;  // a local scene's geometry
  StreamedGeometry streamed;              // a connected client's
  std::unique_ptr<FrameRenderer> renderer, reference;
  PipelineOptions options;
  bool sceneHasFarField = true;  // the scene as a whole reaches beyond d
  bool compare = false;
  bool rebuildOnIntake = false;  // --intake rebuild: the old way, as a baseline
  uint64_t version = ~uint64_t(0);
  uint64_t generation = 0;  // changes whenever the drawn triangles change (OpenGL uploads again)
  size_t rebuilds = 0;      // renderers built (the first included)
  Stopwatch sinceIntake;

  const RenderGeometry& geometry() const { return local ? *local : streamed.geometry(); }
  size_t faces() const {
    if (!local) return streamed.faces();
    std::vector<uint32_t> ids = local->triangles.faceIds;
    std::sort(ids.begin(), ids.end());
    return size_t(std::unique(ids.begin(), ids.end()) - ids.begin());
  }

  void updateFarField() {
    const RenderGeometry& g = geometry();
    const size_t live = local ? g.size() : streamed.liveTriangles();
    options.farFieldAllowed =
        sceneHasFarField && live > 0 && glm::length(g.bounds.extent()) > options.nearDistance;
  }
  // Renderers from scratch over geometry().
  void build() {
    // The renderers hold references to the geometry: drop them first.
    renderer.reset();
    reference.reset();
    updateFarField();
    renderer = std::make_unique<FrameRenderer>(geometry(), options);
    if (compare) {
      PipelineOptions r = options;
      r.mode = RenderMode::RaycastAll;
      reference = std::make_unique<FrameRenderer>(geometry(), r);
    }
    ++rebuilds;
    ++generation;
  }
  // Local: the scene's geometry, drawn as it is.
  void set(RenderGeometry g) {
    renderer.reset();
    reference.reset();
    local = std::make_unique<RenderGeometry>(std::move(g));
    build();
  }
  // Connected: takes up a delta.
  void takeUp(const GeometryDelta& delta) {
    version = delta.version;
    const GeometryChange change = streamed.apply(delta);
    if (!renderer) return build();
    if (change.empty(streamed.geometry().size())) return;
    ++generation;
    if (rebuildOnIntake) {
      streamed.compact();
      return build();
    }
    // Dead slots cost memory and grid entries: compact when they outnumber
    // the live ones (amortised: each compaction follows as many removals).
    if (streamed.deadTriangles() > std::max<size_t>(streamed.liveTriangles(), 65'536)) {
      streamed.compact();
      return build();
    }
    bool ok = renderer->update(change);
    const FrameRenderer::UpdateStats& u = renderer->lastUpdate();
    spdlog::debug(
        "intake: +{} -{} triangles; grid {:.2f} ms, rays {:.2f} ms, horizon {:.2f} ms{}, cache "
        "{:.2f} ms ({} texels forgotten)",
        u.added, u.removed, u.gridMs, u.raysMs, u.horizonMs, u.horizonRebuilt ? " (rebuilt)" : "",
        u.cacheMs, u.texelsForgotten);
    // Too many batches slow the ray query down (each is a BVH of its own).
    if (!ok || renderer->rayBatches() > kMaxRayBatches) {
      streamed.compact();
      return build();
    }
    updateFarField();
    renderer->allowFarField(options.farFieldAllowed);
    if (reference) reference->allowFarField(options.farFieldAllowed);
  }
  // Connected: picks up what arrived (at most every minIntakeS seconds unless forced).
  void refresh(StreamClient& net, bool force, double minIntakeS = 0.1) {
    if (net.version() == version || (!force && sinceIntake.ms() < 1000.0 * minIntakeS)) return;
    takeUp(net.takeDelta());
    sinceIntake = Stopwatch();
  }
};

// Other users in the frames, as animated, self-shadowed avatars: simulated
// walkers beside the path (--avatars N, local), or the users the server
// reports (connected; their models arrive over the connection).
struct Avatars {
  std::unique_ptr<LocalCrowd> crowd;  // local
  StreamClient* net = nullptr;        // connected
  std::unique_ptr<AvatarView> view;
  std::vector<uint8_t> modelTried;  // connected: per offered model, loading was tried
  RenderGeometry dynamic;           // this frame's avatars

  explicit operator bool() const { return view != nullptr; }
  // This frame's avatars at time t (the path's clock) into `dynamic`.
  AvatarFrame build(double t, const Camera& camera, float nearDistance, const RayQuery& rays) {
    view->setRays(&rays);
    if (!net) return view->build(camera, nearDistance, crowd->at(t), dynamic);
    const std::vector<AvatarModelOffer> offers = net->avatarModels();
    modelTried.resize(offers.size(), 0);
    for (size_t k = 0; k < offers.size(); ++k) {
      if (!offers[k].glb || modelTried[k]) continue;
      modelTried[k] = 1;
      try {
        view->setModel(uint16_t(k), std::make_shared<const AvatarModel>(AvatarModel::fromScene(
                                        loadGlbFromMemory(*offers[k].glb, offers[k].name),
                                        offers[k].name, offers[k].heightM)));
        spdlog::info("avatar model {} ({}) arrived", k, offers[k].name);
      } catch (const InputError& e) {
        spdlog::warn("avatar model {} from the server is unusable: {}", offers[k].name, e.what());
      }
    }
    return view->build(camera, nearDistance, net->avatars(), dynamic);
  }
};

// The avatar model: --avatar-model, else the Fox beside the clone
// (VISTREAM_DEFAULT_AVATAR, set at build time).
std::filesystem::path avatarModelPath(const Args& a) {
  if (!a.avatarModel.empty()) return a.avatarModel;
  return VISTREAM_DEFAULT_AVATAR;
}

AvatarShaderOptions avatarShading(const Args& a) {
  AvatarShaderOptions o;
  o.glossExponent = a.avatarGloss;
  return o;
}

Avatars localAvatars(const Args& a, const Scene& scene, const std::vector<PathSample>& path,
                     const RenderGeometry& geometry) {
  Avatars out;
  const std::filesystem::path file = avatarModelPath(a);
  auto model = std::make_shared<const AvatarModel>(
      file == "walker" && !std::filesystem::exists(file)
          ? AvatarModel::fromScene(generateWalker(), "walker", a.avatarHeight)
          : AvatarModel::load(file, a.avatarHeight));
  for (const std::string& w : model->warnings()) spdlog::warn("{}", w);
  const AvatarLight light =
      AvatarLight::of(EnvironmentLight::of(scene.environment), scene.environment);
  out.view = std::make_unique<AvatarView>(model, light, geometry.haze, nullptr, avatarShading(a));
  out.crowd = std::make_unique<LocalCrowd>(path, scene.origin, a.avatars);
  spdlog::info("{} simulated users shown as {} ({} vertices, {} triangles)", a.avatars,
               model->name(), model->vertexCount(), model->triangleCount());
  return out;
}

Avatars remoteAvatars(const Args& a, StreamClient& net, const RenderGeometry& geometry) {
  Avatars out;
  out.net = &net;
  // Without the server's light: the default sky's.
  const AvatarLight light = net.avatarLight().value_or(
      AvatarLight::of(EnvironmentLight::sky(Environment{}.skyColor), Environment{}));
  out.view = std::make_unique<AvatarView>(nullptr, light, geometry.haze, nullptr, avatarShading(a));
  return out;
}

// Headless: software near field, PNG frames, statistics.
int runHeadless(const Args& a, LiveGeometry& live, const std::vector<Camera>& cameras,
                const std::vector<double>& times, glm::ivec2 size, StreamClient* net,
                ConnectionFigures& connection, Avatars& avatars) {
  std::vector<FrameRecord> records;
  ImageRgb8 image, refImage;
  ContactSheetRow sheet(a.sheetFile, cameras.size());
  ProgressBar bar(
      fmt::format("rendering {} frames ({})", cameras.size(), renderModeName(live.options.mode)),
      cameras.size());
  Stopwatch clock;
  for (size_t i = 0; i < cameras.size(); ++i) {
    if (a.realtime && !times.empty()) {  // frame i is due at its path time
      const double due = 1000.0 * (times[i] - times.front()) - clock.ms();
      if (due > 0.0) std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(due));
    }
    if (net) {
      // Each frame waits for the server to complete the view cell it stands in,
      // so a headless walk renders what a patient user would see.
      const glm::vec3 velocity =
          i > 0 ? (cameras[i].eye - cameras[i - 1].eye) * 30.0f : glm::vec3(0.0f);
      net->sendPose(cameras[i].eye, cameras[i].yawDeg, cameras[i].pitchDeg, velocity);
      Stopwatch waited;
      const bool complete = net->waitForCell(a.waitS);
      connection.waitMs += waited.ms();
      ++connection.waits;
      if (!complete) ++connection.timeouts;
      if (!complete && !net->error().empty()) throwInputError("connection lost: {}", net->error());
    }
    FrameRecord r;
    r.frame = i;
    Stopwatch wall;
    if (net) live.refresh(*net, /*force=*/true);
    r.geometryIntakeMs = wall.ms();
    if (net) live.renderer->setImpostors(net->impostorsAt(cameras[i].eye));
    r.report = live.renderer->render(cameras[i], image);
    if (avatars) {
      r.avatars = avatars.build(times[i], cameras[i], live.renderer->polygonDistance(),
                                live.renderer->rays());
      r.avatarPixels = live.renderer->drawDynamic(cameras[i], avatars.dynamic, image);
    }
    r.wallMs = wall.ms();
    if (live.reference) {
      live.reference->render(cameras[i], refImage);
      if (avatars) live.reference->drawDynamic(cameras[i], avatars.dynamic, refImage);
      r.compared = true;
      r.difference = compareImages(image, refImage);
    }
    if (!a.outDir.empty()) writePng(image, std::filesystem::path(a.outDir) / frameName(i));
    r.contrast = imageContrast(image);
    sheet.offer(i, image);
    records.push_back(r);
    bar.advance();
  }
  bar.finish();
  sheet.write();
  if (net) {
    connection.bytesReceived = net->bytesReceived();
    connection.impostorsOffered = net->impostorsOffered();
    connection.impostors = net->impostorFigures();
  }
  printSummary(a, records, live.options, size, net ? &connection : nullptr);
  return 0;
}

// Windowed: OpenGL near field; along a path (frames written if --out) or interactive.
int runWindow(const Args& a, LiveGeometry& live, std::vector<Camera> cameras,
              const std::vector<double>& times, glm::ivec2 size, Camera start, StreamClient* net,
              Avatars& avatars) {
  const PipelineOptions& o = live.options;
  GlWindowOptions wo;
  wo.width = size.x;
  wo.height = size.y;
  wo.title = "vistream";
  wo.vsync = cameras.empty();
  GlWindow window(wo);
  GlRenderer gl;
  gl.upload(live.geometry());
  uint64_t uploaded = live.generation;
  ImageRgb8 farImage;
  std::vector<uint32_t> near;
  GpuImpostors impostors;  // drawn by the point shader
  std::vector<FrameRecord> records;
  if (!cameras.empty()) {
    ContactSheetRow sheet(a.sheetFile, cameras.size());
    for (size_t i = 0; i < cameras.size() && !window.shouldClose(); ++i) {
      if (net) {
        net->sendPose(cameras[i].eye, cameras[i].yawDeg, cameras[i].pitchDeg);
        if (!net->waitForCell(a.waitS) && !net->error().empty())
          throwInputError("connection lost: {}", net->error());
        live.refresh(*net, /*force=*/true);
        if (live.generation != uploaded) {
          gl.upload(live.geometry());
          uploaded = live.generation;
        }
      }
      FrameRecord r;
      r.frame = i;
      if (net) live.renderer->setImpostors(net->impostorsAt(cameras[i].eye));
      r.report = live.renderer->renderFarField(cameras[i], farImage, near, &impostors);
      if (avatars) {
        r.avatars = avatars.build(times[i], cameras[i], live.renderer->polygonDistance(),
                                  live.renderer->rays());
        gl.uploadDynamic(avatars.dynamic);
      }
      gl.draw(cameras[i], farImage, near, live.renderer->polygonDistance(), {}, &impostors);
      if (!a.outDir.empty() || !a.sheetFile.empty()) {
        const ImageRgb8 frame = gl.readBack(size.x, size.y);
        if (!a.outDir.empty()) writePng(frame, std::filesystem::path(a.outDir) / frameName(i));
        r.contrast = imageContrast(frame);
        sheet.offer(i, frame);
      }
      window.swapBuffers();
      Camera ignored = cameras[i];
      window.navigate(ignored, 0.0, 0.0f);
      records.push_back(r);
    }
    sheet.write();
    printSummary(a, records, o, size);
    return 0;
  }
  Camera cam = start;
  Stopwatch clock;
  double last = 0.0, frameMs = 0.0;
  while (!window.shouldClose()) {
    const double now = clock.ms() / 1000.0;
    // Frame time: wall time between frames (pipeline, OpenGL and swap), smoothed.
    frameMs = frameMs == 0.0 ? 1000.0 * (now - last) : 0.9 * frameMs + 100.0 * (now - last);
    window.navigate(cam, now - last, 8.0f);
    last = now;
    cam.width = window.framebufferWidth();
    cam.height = window.framebufferHeight();
    if (cam.width < 16 || cam.height < 16) continue;
    if (net) {
      if (!net->error().empty()) throwInputError("connection lost: {}", net->error());
      net->sendPose(cam.eye, cam.yawDeg, cam.pitchDeg);
      live.refresh(*net, /*force=*/false);
      if (live.generation != uploaded) {
        gl.upload(live.geometry());
        uploaded = live.generation;
      }
    }
    if (net) live.renderer->setImpostors(net->impostorsAt(cam.eye));
    const FrameReport rep = live.renderer->renderFarField(cam, farImage, near, &impostors);
    std::string avatarWhy = "no dynamic objects";
    if (avatars) {
      avatarWhy =
          avatars.build(now, cam, live.renderer->polygonDistance(), live.renderer->rays()).why;
      gl.uploadDynamic(avatars.dynamic);
    }
    const PixelCounts& p = rep.pixels;
    std::vector<HudLine> hud = {
        {fmt::format("frame {:.1f} ms (pipeline {:.1f} ms)  near {} triangles  d = {:.0f} m",
                     frameMs, rep.ms.total, rep.nearTriangles, o.nearDistance)},
        {fmt::format("pixels: polygon {}  horizon {}  cache {}  ray hit {}  ray miss {}", p.polygon,
                     p.horizon, p.cache, p.rayHit, p.rayMiss)},
        {fmt::format("faces held {}  received {:.1f} MB  far field {}  horizon {}  cache {}",
                     live.faces(), net ? double(net->bytesReceived()) / 1e6 : 0.0,
                     rep.farFieldRan ? "on" : "off", rep.horizonRan ? "on" : "off",
                     rep.cacheRan ? "on" : "off")},
        {"avatars: " + avatarWhy},
    };
    gl.draw(cam, farImage, near, live.renderer->polygonDistance(), hud, &impostors);
    window.swapBuffers();
  }
  return 0;
}

int run(const Args& a) {
  // With --host, --scene only serves --path auto (the path is generated
  // through the free space of the local copy; geometry still streams).
  const bool connected = !a.host.empty(), local = !a.scene.empty() && !connected;
  if (!local && !connected) throwInputError("give either --scene (local) or --host (connected)");
  if (connected && !a.scene.empty() && a.pathFile != "auto")
    throwInputError(
        InputErrorCode::BadArgument,
        "--scene with --host is used only to generate --path auto; give --path auto, or drop "
        "--scene");
  if (a.headless && a.pathFile.empty())
    throwInputError("--headless needs --path (a path file, or auto)");
  if (a.avatars > 0 && !local)
    throwInputError(InputErrorCode::BadArgument,
                    "--avatars simulates users in a local scene: give --scene, not --host "
                    "(a connected client shows the users the server reports)");
  if (a.avatars > 0 && a.pathFile.empty())
    throwInputError("--avatars needs --path: the simulated users walk beside it");
  if (a.avatars > 0 && avatarModelPath(a) != "walker" &&
      !std::filesystem::exists(avatarModelPath(a)))
    throwInputError("--avatars: the avatar model {} does not exist (give --avatar-model)",
                    avatarModelPath(a).string());
  const glm::ivec2 size = parseImageSize(a.size);
  const RenderMode mode = parseMode(a.mode);
  // Numbers are range-checked at parse time (see runClientTool).
  if (!a.outDir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(a.outDir, ec);
    if (ec) throwInputError("--out {}: cannot create it: {}", a.outDir, ec.message());
  }

  std::optional<Scene> scene;
  std::unique_ptr<StreamClient> net;
  RenderGeometry geometry;
  glm::dvec3 origin(0.0);
  ConnectionFigures connection;
  std::optional<Scene> pathScene;  // connected: the local copy --path auto walks through
  if (local) {
    scene = openScene(a.scene, a.sceneLimits);
    geometry = renderGeometryFromScene(*scene, {}, a.lightingCache);
    origin = scene->origin;
  } else {
    if (!a.scene.empty()) pathScene = openScene(a.scene, a.sceneLimits);
    StreamClientOptions so;
    so.host = a.host;
    so.port = a.port;
    so.token = a.token;
    so.radius = a.streamRadius;
    so.wantsAvatars = !a.noAvatars;
    so.reconnect = !a.noReconnect;
    so.wantsImpostors = mode != RenderMode::ImpostorOff;
    net = std::make_unique<StreamClient>(so);
    origin = net->origin();
  }
  std::vector<PathSample> path;
  if (!a.pathFile.empty()) {
    path = loadPath(a, scene ? &*scene : (pathScene ? &*pathScene : nullptr), a.frames);
    if (path.empty()) throwInputError("--path {}: no rows", a.pathFile);
    if (a.frames > path.size())
      throwInputError("--frames {}: the path has only {} rows", a.frames, path.size());
    if (a.frames) path.resize(a.frames);
  }
  std::vector<Camera> cameras = camerasFromPath(path, origin, size.x, size.y, a.vfov);
  PipelineOptions o = pipelineOptions(a, scene ? &*scene : nullptr, mode);
  if (net) {
    // Connected: walk the path's first pose until the server's data for it has arrived.
    Camera first;
    if (!cameras.empty()) first = cameras.front();
    net->sendPose(first.eye, first.yawDeg, first.pitchDeg);
    Stopwatch waited;
    const bool complete = net->waitForCell(a.waitS);
    connection.waitMs += waited.ms();
    ++connection.waits;
    if (!complete) ++connection.timeouts;
    if (!complete)
      spdlog::warn(
          "the server did not complete the first view cell within {:.0f} s; rendering what arrived",
          a.waitS);
    if (!(a.nearDistance > 0.0f)) o.nearDistance = std::min(150.0f, 0.5f * net->radius());
  }
  LiveGeometry live;
  live.options = o;
  live.sceneHasFarField = o.farFieldAllowed;
  live.compare = a.compare;
  live.rebuildOnIntake = a.intake == "rebuild";
  if (net) {
    live.takeUp(net->takeDelta());
    spdlog::info("holding {} triangles from {}:{}", live.geometry().size(), a.host, a.port);
  } else {
    live.set(std::move(geometry));
    // The server decides this for a connected client (Welcome.ground_y); the
    // local client with the ray query its renderer built.
    const GroundPlane ground = decideGround(*scene, live.renderer->rays(), a.ground);
    live.local->groundY = ground.y;
    if (ground.y) spdlog::info("ground {}", ground.why);
  }
  Avatars avatars;
  if (a.avatars > 0) avatars = localAvatars(a, *scene, path, live.geometry());
  if (net && !a.noAvatars) avatars = remoteAvatars(a, *net, live.geometry());
  std::vector<double> times;
  for (const PathSample& s : path) times.push_back(s.t);
  if (a.headless) return runHeadless(a, live, cameras, times, size, net.get(), connection, avatars);
  Camera start;
  start.width = size.x;
  start.height = size.y;
  start.vfovDeg = a.vfov;
  if (!cameras.empty())
    start = cameras.front();
  else if (!live.geometry().bounds.empty())
    start.eye = live.geometry().bounds.center();
  return runWindow(a, live, cameras, times, size, start, net.get(), avatars);
}

}  // namespace
}  // namespace vistream

namespace vistream {

int runClientTool(int argc, char** argv) {
  using namespace vistream;
  Args a;
  CLI::App app{
      "vistream-client: renders a walkthrough; near field as polygons, far field by horizon "
      "tracing, a panoramic "
      "image cache and ray casting (Wimmer 2001, chapter 4)"};
  showDefaultsInHelp(app);
  app.add_option(
      "--scene", a.scene,
      "local mode: a SCENE (with --host: used only to generate --path auto). " + sceneSpecHelp());
  addSceneLimitsOption(app, a.sceneLimits);
  addLightingCacheOption(app, a.lightingCache);
  addGroundOption(app, a.ground);
  app.add_option("--host", a.host, "connected mode: the vistream-server to stream from");
  app.add_option("--port", a.port, "the server's port")->check(tcpPort());
  app.add_option("--token", a.token, "the server's shared secret, if it asks for one");
  app.add_flag("--headless", a.headless,
               "no window: software near field, PNG frames and statistics");
  app.add_option("--path", a.pathFile, "path file (CSV t,x,y,z,yaw_deg,pitch_deg), or auto");
  app.add_option("--frames", a.frames, "frames to render")
      ->check(atLeast<size_t>(1))
      ->default_str("every row of the path; 300 for auto");
  app.add_option("--size", a.size, "image size WIDTHxHEIGHT");
  app.add_option("--fov", a.vfov, "vertical field of view, degrees")->check(between(1.0, 170.0));
  app.add_option("--out", a.outDir, "write DIR/frame_00000.png, ...");
  app.add_option("--sheet", a.sheetFile,
                 "contact sheet: a PNG row of 4 frames evenly spaced along the path, added "
                 "below the rows FILE already holds");
  app.add_flag("--json", a.json,
               "print one JSON object (frames, mean_frame_ms, pixels, per_frame, ...)");
  app.add_option("--mode", a.mode,
                 "pipeline | raycast-all | geometry-all | impostor-off (the pipeline without "
                 "impostors; connected, the server then sends the far geometry they replace)");
  app.add_option("--near-distance", a.nearDistance, "near-field distance d, metres")
      ->check(positive())
      ->default_str("the scene's, or the server's");
  app.add_option("--stream-radius", a.streamRadius,
                 "connected: radius the server streams within, metres; the far field is what "
                 "arrives beyond --near-distance")
      ->check(positive())
      ->default_str("the server's");
  app.add_option("--pixel-budget", a.pixelBudget, "rays a frame for refreshing cached pixels")
      ->check(atLeast<size_t>(0));
  app.add_option("--polygon-budget", a.polygonBudget,
                 "scenes with at most this many triangles are drawn whole, without a far field (0: "
                 "always split at d)")
      ->check(atLeast<size_t>(0));
  app.add_flag("--no-cache", a.noCache,
               "switch the panoramic image cache off (trace every far-field pixel)");
  app.add_option(
         "--max-stale-px", a.maxStalePixels,
         "cached pixels expire when far-field geometry at d may have moved this many pixels")
      ->check(nonNegative());
  app.add_option("--horizon-cell", a.horizonCell,
                 "height-field cell size for horizon tracing, metres")
      ->check(positive());
  app.add_option("--horizon-subsample", a.horizonSubsample, "trace every k-th column while moving")
      ->check(atLeast(1));
  app.add_option("--path-speed", a.pathSpeed, "relative walking speed of --path auto")
      ->check(positive());
  app.add_option("--intake", a.intake,
                 "connected: take up arriving geometry incrementally, or rebuild the renderer "
                 "for every change (the old way, a baseline for benchmarks)")
      ->check(CLI::IsMember({"incremental", "rebuild"}));
  app.add_option("--wait", a.waitS, "connected: seconds to wait for each view cell")
      ->check(nonNegative());
  app.add_flag("--compare", a.compare,
               "also render raycast-all and report the image error of every frame");
  app.add_option("--avatars", a.avatars,
                 "local: N simulated users walking beside the path, drawn as animated, "
                 "self-shadowed avatars")
      ->check(CLI::Range(size_t(0), size_t(1000)));
  app.add_flag("--realtime", a.realtime,
               "headless: render each frame at its path time (t), as a user walking would, "
               "rather than as fast as possible");
  app.add_flag("--no-avatars", a.noAvatars,
               "connected: neither ask the server for other users nor draw them");
  app.add_flag("--no-reconnect", a.noReconnect,
               "connected: end when the server goes away; without this flag the client "
               "reconnects with backoff (through a proxy perhaps to another replica), keeping "
               "what it holds and drawing it meanwhile");
  app.add_option("--avatar-model", a.avatarModel,
                 "the avatars' skinned glTF model, or 'walker' (a built-in figure)")
      ->default_str(std::filesystem::path(VISTREAM_DEFAULT_AVATAR).filename().string() +
                    " beside the clone (../shared/data)");
  app.add_option("--avatar-height", a.avatarHeight, "the avatars' height, metres")
      ->check(between(0.1, 10.0));
  app.add_option("--avatar-gloss", a.avatarGloss,
                 "a glossy term on the avatars: the Phong exponent of a self-shadowed lobe about "
                 "the viewer's reflection (e.g. 16; 0: diffuse only; at most 256, where the "
                 "lobe becomes narrower than a mask pixel)")
      ->check(between(0.0, 256.0));
  app.add_option("--log-level", a.logLevel, "trace, debug, info, warn, error, critical, off");
  return runFlatToolApp("vistream-client", app, argc, argv, a.logLevel, [&] { return run(a); });
}

}  // namespace vistream
