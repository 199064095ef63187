// bench_impostor_image: what point-based impostors (Wimmer 2001, chapter 5)
// buy in the image, and what they cost in time, against the alternatives a
// thin client has for the far field.
//
// One view cell of a scene is baked (the server's PVS and placement, as
// `vistream-pvs impostors --cell` does); then a walk through the cell (the
// cell's diagonal, the heading turning once round) is drawn five ways, each
// frame against a ray-cast reference with 4x4 samples a pixel (box filter)
// over every triangle of the scene:
//   impostors    the connected client: the PVS without the faces the
//                impostors replace, plus the impostors as the client decodes
//                them (the pipeline);
//   geometry     the replaced faces drawn as raw polygons, one sample a pixel
//                (the aliasing of the thesis's Figures 5.13-5.15);
//   ray-cast     today's far field: the PVS in the pipeline, far field ray
//                cast with the image cache and horizon tracing;
//   held-only    the connected client without impostors (its far field is
//                empty where the impostors' geometry was);
// Error is measured on the impostors' footprint (pixels where any reference
// sample meets a replaced face) and over the whole frame. `--sweep` bakes the
// heaviest impostor once per knob setting (LDI resolution, point removal,
// texture size, variance threshold, the precision kept: position error and
// colour step) and reports the same error against bake time and bytes.
//
// It lives with the tests because it needs both sides: the server's bake
// and the client's renderers (server/ and client/ never include each other).

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <nlohmann/json.hpp>
#include <numeric>

#include "client/app/walkthrough.h"
#include "client/farfield/pipeline.h"
#include "client/gl/gl_renderer.h"
#include "client/gl/gl_window.h"
#include "client/render/image.h"
#include "client/render/impostor_splat.h"
#include "common/cmd/cli.h"
#include "common/core/median.h"
#include "common/core/progress.h"
#include "common/generate/scene_spec.h"
#include "protocol/impostor/impostor_codec.h"
#include "server/cmd/scene_boxes.h"
#include "server/impostor/impostor_world.h"

namespace vistream {
namespace {

using nlohmann::json;

struct Args {
  std::string scene = "bigcity";
  std::string cell = "0,1,0,4,3,4";
  size_t frames = 12;
  size_t repeats = 1;  // walks of the same frames, for more time samples
  std::string size = "320x240";
  int supersample = 4;
  std::string png;
  bool json = false;
  bool sweep = false;
  bool gl = false;
  ImpostorPlacementOptions placement;
  std::string lightingCache = defaultLightingCacheDir().string();
};

// A subset of the world's triangles with their colours and the backdrop.
RenderGeometry subset(const ImpostorScene& view, const std::vector<uint32_t>& triangles) {
  RenderGeometry g;
  for (uint32_t t : triangles) appendTriangle(g, view.triangles, view.lighting, t);
  setBackdrop(g, view.backdrop);
  g.groundY = view.groundY;
  return g;
}

std::vector<uint32_t> without(const std::vector<uint32_t>& all, const std::vector<bool>& drop) {
  std::vector<uint32_t> out;
  for (uint32_t t : all)
    if (!drop[t]) out.push_back(t);
  return out;
}

// The reference frame: k x k rays a pixel over every triangle, box
// filtered, and the footprint: pixels where a sample meets a marked triangle
// (kInside: every sample does; kOutline: some do, some meet other triangles
// or the sky, the silhouettes of the marked geometry).
struct Reference {
  ImageRgb8 image;
  std::vector<uint8_t> footprint;
  size_t footprintPixels = 0;
  static constexpr uint8_t kInside = 1, kOutline = 2;
};

Reference reference(const RenderGeometry& all, const RayQuery& rays,
                    const std::vector<bool>& marked, const Camera& c, int k) {
  Reference r;
  r.image = ImageRgb8(c.width, c.height);
  r.footprint.assign(size_t(c.width) * size_t(c.height), 0);
  const Camera::PixelRays pr = c.pixelRays();
  tbb::parallel_for(0, c.height, [&](int y) {
    for (int x = 0; x < c.width; ++x) {
      glm::vec3 sum(0.0f);
      int marks = 0;
      for (int sy = 0; sy < k; ++sy)
        for (int sx = 0; sx < k; ++sx) {
          const glm::vec3 dir = pr.at(float(x) + (float(sx) + 0.5f) / float(k),
                                      float(y) + (float(sy) + 0.5f) / float(k));
          const Hit h = rays.firstHit(Ray{c.eye, dir, 0.0f, 1e30f});
          glm::u8vec3 colour;
          if (h.valid()) {
            colour = all.colourAt(h.triangle, h.u, h.v, h.t * glm::length(dir));
            marks += marked[h.triangle];
          } else {
            colour = all.background(c.eye, dir);
          }
          sum += glm::vec3(colour);
        }
      r.image.set(x, y, glm::u8vec3(glm::round(sum / float(k * k))));
      r.footprint[size_t(y) * size_t(c.width) + size_t(x)] = marks == 0       ? 0
                                                             : marks == k * k ? Reference::kInside
                                                                              : Reference::kOutline;
    }
  });
  r.footprintPixels = size_t(
      std::count_if(r.footprint.begin(), r.footprint.end(), [](uint8_t f) { return f != 0; }));
  return r;
}

// Sums of a frame's error against the reference (8-bit levels, the mean
// over channels per pixel).
struct ErrorSums {
  double footAbs = 0, footSq = 0, frameAbs = 0, outlineAbs = 0;
  size_t footPixels = 0, footWrong = 0, framePixels = 0, outlinePixels = 0;
  void add(const ImageRgb8& image, const Reference& ref) {
    for (int y = 0; y < image.height; ++y)
      for (int x = 0; x < image.width; ++x) {
        const glm::vec3 d = glm::abs(glm::vec3(image.at(x, y)) - glm::vec3(ref.image.at(x, y)));
        const double e = (d.x + d.y + d.z) / 3.0;
        frameAbs += e;
        ++framePixels;
        const uint8_t f = ref.footprint[size_t(y) * size_t(image.width) + size_t(x)];
        if (!f) continue;
        if (f == Reference::kOutline) {
          outlineAbs += e;
          ++outlinePixels;
        }
        footAbs += e;
        footSq += (double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z) / 3.0;
        ++footPixels;
        footWrong += std::max({d.x, d.y, d.z}) > 32.0f;
      }
  }
  double footMae() const { return footPixels ? footAbs / double(footPixels) : 0.0; }
  double footRmse() const { return footPixels ? std::sqrt(footSq / double(footPixels)) : 0.0; }
  double footWrongShare() const {
    return footPixels ? double(footWrong) / double(footPixels) : 0.0;
  }
  double frameMae() const { return framePixels ? frameAbs / double(framePixels) : 0.0; }
  // The footprint's silhouette pixels (Reference::kOutline) and the rest.
  double outlineMae() const { return outlinePixels ? outlineAbs / double(outlinePixels) : 0.0; }
  double insideMae() const {
    return footPixels > outlinePixels ? (footAbs - outlineAbs) / double(footPixels - outlinePixels)
                                      : 0.0;
  }
};

struct ModeResult {
  std::string name;
  ErrorSums error;
  std::vector<double> ms;
  StageTimes stages;  // summed over the frames
  std::vector<StageTimes> perFrame;
  std::vector<uint8_t> splatted;  // per frame: the impostor splat ran
  std::vector<ImageRgb8> frames;
};

std::vector<Camera> walk(const Box3f& cell, size_t frames, int width, int height) {
  std::vector<Camera> out;
  for (size_t k = 0; k < frames; ++k) {
    const float s = frames > 1 ? float(k) / float(frames - 1) : 0.5f;
    Camera c;
    c.width = width;
    c.height = height;
    const glm::vec3 lo = glm::mix(cell.lo, cell.hi, 0.1f), hi = glm::mix(cell.lo, cell.hi, 0.9f);
    c.eye = glm::mix(lo, hi, s);
    c.eye.y = 0.5f * (cell.lo.y + cell.hi.y);
    c.yawDeg = 360.0f * float(k) / float(frames);
    c.pitchDeg = 2.0f;
    out.push_back(c);
  }
  return out;
}

// The camera turned (about the vertical) to look at `target`.
Camera facing(Camera c, const glm::vec3& target) {
  const glm::vec3 to = target - c.eye;
  c.yawDeg = glm::degrees(std::atan2(-to.x, -to.z));  // forward is (-sin yaw, ., -cos yaw)
  return c;
}

PipelineOptions pipelineOptions(RenderMode mode, float nearDistance) {
  PipelineOptions o;
  o.mode = mode;
  o.nearDistance = nearDistance;
  o.polygonBudget = 0;  // split at d, as a client of a large scene does
  return o;
}

double medianOf(std::vector<double> v) {
  return v.empty() ? 0.0 : median(v);
}

// One frame rendered and timed (wall clock; its stage times summed into m).
double timedRender(FrameRenderer& renderer, const Camera& camera, ImageRgb8& image, ModeResult& m) {
  const auto start = std::chrono::steady_clock::now();
  const FrameReport rep = renderer.render(camera, image);
  const double wall =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  m.stages += rep.ms;
  m.perFrame.push_back(rep.ms);
  m.splatted.push_back(rep.impostorsRan);
  return wall;
}

// The same, its error against the reference counted and the frame kept if asked.
void renderInto(ModeResult& m, FrameRenderer& renderer, const Camera& camera, const Reference& ref,
                bool keepFrame) {
  ImageRgb8 image;
  m.ms.push_back(timedRender(renderer, camera, image, m));
  m.error.add(image, ref);
  if (keepFrame) m.frames.push_back(std::move(image));
}

// Draws the walk with `renderer`, against the references.
ModeResult runMode(const std::string& name, FrameRenderer& renderer,
                   const std::vector<Camera>& cameras, const std::vector<Reference>& refs,
                   bool keepFrames) {
  ModeResult m;
  m.name = name;
  for (size_t i = 0; i < cameras.size(); ++i)
    renderInto(m, renderer, cameras[i], refs[i], keepFrames);
  return m;
}

// Every mode along the walk, frame by frame: frame i in each mode (the
// first mode rotating from frame to frame) before frame i + 1, so that the
// machine's load falls on all modes alike and their times pair up frame by
// frame. `out` (one a mode) gathers the times; the first walk (firstWalk)
// also counts the error and keeps the frames if asked.
void walkModes(const std::vector<FrameRenderer*>& modes, const std::vector<Camera>& cameras,
               const std::vector<Reference>& refs, bool firstWalk, bool keepFrames,
               std::vector<ModeResult>& out) {
  for (size_t i = 0; i < cameras.size(); ++i)
    for (size_t j = 0; j < modes.size(); ++j) {
      const size_t k = (i + j) % modes.size();
      if (firstWalk) {
        renderInto(out[k], *modes[k], cameras[i], refs[i], keepFrames);
      } else {
        ImageRgb8 image;
        out[k].ms.push_back(timedRender(*modes[k], cameras[i], image, out[k]));
      }
    }
}

// The median over frames of one mode's frame time over another's on the
// same frame (both walked by walkModes); with `only`, over the frames where
// that mode's impostor splat ran.
double medianRatio(const ModeResult& of, const ModeResult& to, const ModeResult* only = nullptr) {
  std::vector<double> r;
  for (size_t i = 0; i < std::min(of.ms.size(), to.ms.size()); ++i)
    if (to.ms[i] > 0.0 && (!only || (i < only->splatted.size() && only->splatted[i])))
      r.push_back(of.ms[i] / to.ms[i]);
  return medianOf(r);
}

// The crop (at most 120 x 90 pixels, where the footprint is densest) of
// every mode's frame, scaled 3x, side by side.
ImageRgb8 crops(const Reference& ref, const std::vector<const ImageRgb8*>& frames) {
  const int w = ref.image.width, h = ref.image.height;
  const int cw = std::min(w, 120), ch = std::min(h, 90);
  // Footprint pixels per window, from a summed-area table.
  std::vector<uint32_t> sum(size_t(w + 1) * size_t(h + 1), 0);
  auto at = [&](int x, int y) -> uint32_t& { return sum[size_t(y) * size_t(w + 1) + size_t(x)]; };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      at(x + 1, y + 1) = at(x, y + 1) + at(x + 1, y) - at(x, y) +
                         (ref.footprint[size_t(y) * size_t(w) + size_t(x)] != 0);
  uint32_t best = 0;
  int cx = 0, cy = 0;
  for (int y = 0; y + ch <= h; y += 2)
    for (int x = 0; x + cw <= w; x += 2) {
      const uint32_t n = at(x + cw, y + ch) - at(x, y + ch) - at(x + cw, y) + at(x, y);
      if (n > best) {
        best = n;
        cx = x;
        cy = y;
      }
    }
  if (best == 0) return {};
  constexpr int kScale = 3;
  std::vector<ImageRgb8> tiles;
  for (const ImageRgb8* f : frames) {
    ImageRgb8 t(cw * kScale, ch * kScale);
    for (int y = 0; y < ch * kScale; ++y)
      for (int x = 0; x < cw * kScale; ++x) t.set(x, y, f->at(cx + x / kScale, cy + y / kScale));
    tiles.push_back(std::move(t));
  }
  return contactSheet(tiles, int(tiles.size()));
}

// Per stage, the median over a mode's frames (with `only`, over the frames
// where that mode's impostor splat ran).
json medianStages(const ModeResult& m, const ModeResult* only = nullptr) {
  json stages = json::object();
  StageTimes{}.forEachField([&](const StatField& f, double) {
    std::vector<double> v;
    for (size_t i = 0; i < m.perFrame.size(); ++i) {
      if (only && !(i < only->splatted.size() && only->splatted[i])) continue;
      m.perFrame[i].forEachField([&](const StatField& g, double x) {
        if (g.key == f.key) v.push_back(x);
      });
    }
    stages[std::string(f.key)] = medianOf(v);
  });
  return stages;
}

json errorJson(const ModeResult& m) {
  const double n = double(std::max<size_t>(1, m.ms.size()));
  return {{"mode", m.name},
          {"footprint_mae", m.error.footMae()},
          {"footprint_rmse", m.error.footRmse()},
          {"footprint_wrong_share", m.error.footWrongShare()},
          {"outline_mae", m.error.outlineMae()},
          {"inside_mae", m.error.insideMae()},
          {"frame_mae", m.error.frameMae()},
          {"median_frame_ms", medianOf(m.ms)},
          {"mean_stage_ms",
           {{"near", (m.stages.nearSelect + m.stages.nearDraw + m.stages.shade) / n},
            {"opacity", m.stages.opacity / n},
            {"horizon", m.stages.horizon / n},
            {"cache", m.stages.cache / n},
            {"raycast", m.stages.raycast / n},
            {"impostors", m.stages.impostors / n},
            {"compose", m.stages.compose / n},
            {"total", m.stages.total / n}}},
          {"median_stage_ms", medianStages(m)}};
}

struct SweepRow {
  std::string knob, value;
  ImpostorOptions options;
  PointSplat splat;
};

// Holes: footprint pixels that every reference sample sees on the
// impostors' faces (Reference::kInside) but no point of theirs covers.
size_t holes(const std::vector<std::shared_ptr<const Impostor>>& impostors,
             const std::vector<Camera>& cameras, const std::vector<Reference>& refs,
             const PointSplat& splat) {
  size_t count = 0;
  ImageRgb8 scratch;
  for (size_t i = 0; i < cameras.size(); ++i) {
    ImpostorSplatter s;
    s.begin(cameras[i], nullptr, splat);
    scratch = ImageRgb8(cameras[i].width, cameras[i].height);
    for (const auto& imp : impostors) s.draw(*imp, scratch);
    for (size_t p = 0; p < refs[i].footprint.size(); ++p)
      count +=
          refs[i].footprint[p] == Reference::kInside && !(s.depth()[p] < ImpostorSplatter::kEmpty);
  }
  return count;
}

std::vector<SweepRow> sweepRows(const ImpostorOptions& base) {
  std::vector<SweepRow> rows;
  auto add = [&](std::string knob, std::string value, auto&& change) {
    SweepRow r{std::move(knob), std::move(value), base, PointSplat{}};
    change(r.options);
    rows.push_back(std::move(r));
  };
  add("defaults", "-", [](ImpostorOptions&) {});
  for (float f : {0.5f, 0.7f, 0.8f, 1.0f, 1.4f})
    add("resolution", fmt::format("{}", f), [f](ImpostorOptions& o) { o.resolutionFactor = f; });
  add("removal", "off", [](ImpostorOptions& o) { o.removePoints = false; });
  // A coarser sampling with the splat widened to match (0.7 / 0.8 pixels):
  // fewer points, wider silhouettes.
  add("res+radius", "0.8/0.88", [](ImpostorOptions& o) { o.resolutionFactor = 0.8f; });
  rows.back().splat.radius = 0.7f / 0.8f;
  for (const glm::uvec2 texture : {glm::uvec2(1, 1), glm::uvec2(4, 2), glm::uvec2(16, 4)})
    add("texture", fmt::format("{}x{}", texture.x, texture.y), [texture](ImpostorOptions& o) {
      o.textureWidth = texture.x;
      o.textureHeight = texture.y;
    });
  for (float v : {2.0f, 8.0f})
    add("variance", fmt::format("{}", v), [v](ImpostorOptions& o) { o.varianceThreshold = v; });
  add("filter", "0.5", [](ImpostorOptions& o) { o.pixelFilterSigma = 0.5f; });  // the thesis's
  // The precision the bake keeps (and the encoding carries): the points'
  // grid in pixels, the textures' colour step in levels.
  for (float e : {1e-4f, 0.2f})
    add("position", fmt::format("{}", e), [e](ImpostorOptions& o) { o.positionError = e; });
  for (uint32_t c : {1u, 16u})
    add("colour", fmt::format("{}", c), [c](ImpostorOptions& o) { o.colourStep = c; });
  // The client's splat (the bake unchanged).
  for (float r : {0.5f, 0.75f, 0.95f}) {
    add("radius", fmt::format("{}", r), [](ImpostorOptions&) {});
    rows.back().splat.radius = r;
  }
  add("same surf", "0", [](ImpostorOptions&) {});
  rows.back().splat.sameSurface = 0.0f;
  return rows;
}

int run(const Args& a) {
  const Box3d fileCell = parseFileBox(a.cell, "--cell");
  const glm::ivec2 wh = parseImageSize(a.size);
  const int width = wh.x, height = wh.y;
  const Scene scene = openScene(a.scene);
  warnIfOutsideScene(scene, fileCell, "--cell", a.cell);
  const Box3f cell = toLocal(scene, fileCell);
  const ImpostorWorld world(scene, {GroundChoice{}, LightingOptions{}, a.lightingCache});
  const ImpostorScene view = world.view();
  ImpostorOptions bake;
  bake.screen.width = width;
  bake.screen.height = height;

  spdlog::info("baking the impostors of cell {} in {}", a.cell, scene.name);
  const CellImpostors baked = world.bakeCell(cell, a.placement, bake);
  if (baked.impostors.empty()) {
    fmt::print(stderr, "bench_impostor_image: the cell has no impostor: {}\n", baked.placement.why);
    return 1;
  }
  const std::vector<uint32_t> pvs = world.pvsTriangles(cell);
  std::vector<bool> replaced(view.triangles.size(), false);
  size_t impostorBytes = 0, geometryBytes = 0;
  for (size_t i = 0; i < baked.impostors.size(); ++i) {
    for (uint32_t t : world.trianglesOfFaces(baked.replacedFaces[i])) replaced[t] = true;
    impostorBytes += baked.stats[i].bytes;
    geometryBytes += baked.geometryBytes[i];
  }
  std::vector<uint32_t> every(view.triangles.size());
  std::iota(every.begin(), every.end(), 0u);
  const RenderGeometry all = subset(view, every);
  const RenderGeometry pvsGeometry = subset(view, pvs);
  const RenderGeometry held = subset(view, without(pvs, replaced));
  auto set = std::make_shared<ImpostorSet>();
  set->cell = cell;
  // What a client draws: each impostor through the wire encoding (the same
  // points, in the encoding's Morton order, which keeps a block of points
  // together on the screen).
  for (const Impostor& imp : baked.impostors) {
    auto decoded = std::make_shared<Impostor>();
    std::string error;
    if (!wire::decodeImpostor(wire::encodeImpostor(imp), *decoded, error)) {
      fmt::print(stderr, "bench_impostor_image: an impostor does not decode: {}\n", error);
      return 1;
    }
    set->impostors.push_back(std::move(decoded));
  }
  set->expected = uint32_t(baked.impostors.size());

  const std::vector<Camera> cameras = walk(cell, a.frames, width, height);
  const auto rays = makeEmbreeRayQuery(all.triangles);
  std::vector<Reference> refs;
  {
    ProgressBar bar("reference frames", cameras.size());
    for (const Camera& c : cameras) {
      refs.push_back(reference(all, *rays, replaced, c, a.supersample));
      bar.advance();
    }
    bar.finish();
  }
  const float d = a.placement.nearDistance;
  const bool png = !a.png.empty();
  std::vector<ModeResult> modes(4);
  modes[0].name = "impostors";
  modes[1].name = "geometry";
  modes[2].name = "ray-cast";
  modes[3].name = "held-only";
  {
    // Each walk with renderers of its own, so that every walk starts from
    // an empty image cache, as the first does.
    ProgressBar bar("walks", a.repeats);
    for (size_t w = 0; w < a.repeats; ++w) {
      FrameRenderer withImpostors(held, pipelineOptions(RenderMode::Pipeline, d));
      withImpostors.setImpostors(set);
      FrameRenderer geometryAll(pvsGeometry, pipelineOptions(RenderMode::GeometryAll, d));
      FrameRenderer rayCast(pvsGeometry, pipelineOptions(RenderMode::ImpostorOff, d));
      FrameRenderer heldOnly(held, pipelineOptions(RenderMode::ImpostorOff, d));
      walkModes({&withImpostors, &geometryAll, &rayCast, &heldOnly}, cameras, refs, w == 0, png,
                modes);
      bar.advance();
    }
    bar.finish();
  }
  constexpr size_t kRayCast = 2;  // the baseline of the frame-time ratios
  // The splat alone, per impostor: software points a second.
  std::vector<double> splatMs(baked.impostors.size());
  for (size_t i = 0; i < baked.impostors.size(); ++i) {
    std::vector<double> ms;
    for (const Camera& c : cameras) {
      const Camera towards = facing(c, baked.impostors[i].box.center());
      ImpostorSplatter s;
      ImageRgb8 image(width, height);
      const auto start = std::chrono::steady_clock::now();
      s.begin(towards);
      s.draw(*set->impostors[i], image);
      ms.push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
              .count());
    }
    splatMs[i] = medianOf(ms);
  }
  // The same by the OpenGL point shader: a frame with the impostor against
  // the same frame without it (far-field image and limits uploaded in both).
  std::vector<double> glMs;
  if (a.gl) {
    GlWindow window(GlWindowOptions{width, height, "bench_impostor_image", false, false});
    GlRenderer gl;
    gl.upload(RenderGeometry{});
    const ImageRgb8 far(width, height, held.sky);
    GpuImpostors none;
    none.depthLimit.assign(size_t(width) * size_t(height), std::numeric_limits<float>::infinity());
    auto timed = [&](const Camera& c, const GpuImpostors& gpu) {
      gl.draw(c, far, {}, std::numeric_limits<float>::infinity(), {}, &gpu);
      gl.finish();
      const auto start = std::chrono::steady_clock::now();
      for (int k = 0; k < 3; ++k)
        gl.draw(c, far, {}, std::numeric_limits<float>::infinity(), {}, &gpu);
      gl.finish();
      return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                 .count() /
             3.0;
    };
    for (size_t i = 0; i < baked.impostors.size(); ++i) {
      GpuImpostors one = none;
      one.impostors.push_back(set->impostors[i]);
      std::vector<double> with, without;
      for (const Camera& c : cameras) {
        const Camera towards = facing(c, baked.impostors[i].box.center());
        with.push_back(timed(towards, one));
        without.push_back(timed(towards, none));
      }
      glMs.push_back(std::max(0.0, medianOf(with) - medianOf(without)));
    }
  }

  if (png) {
    size_t best = 0;
    for (size_t i = 0; i < refs.size(); ++i)
      if (refs[i].footprintPixels > refs[best].footprintPixels) best = i;
    std::vector<const ImageRgb8*> frames{&refs[best].image};
    for (const ModeResult& m : modes) frames.push_back(&m.frames[best]);
    const ImageRgb8 sheet = crops(refs[best], frames);
    if (sheet.width > 0) {
      writePng(sheet, a.png);
      spdlog::info("wrote {} (frame {}: reference, {})", a.png, best,
                   "impostors, geometry, "
                   "ray-cast, held-only");
    }
  }

  // The knob sweep on the heaviest impostor.
  json sweep = json::array();
  if (a.sweep) {
    size_t heaviest = 0;
    for (size_t i = 0; i < baked.impostors.size(); ++i)
      if (baked.placement.sites[baked.siteOf[i]].triangles.size() >
          baked.placement.sites[baked.siteOf[heaviest]].triangles.size())
        heaviest = i;
    const ImpostorSite& site = baked.placement.sites[baked.siteOf[heaviest]];
    std::vector<bool> mine(view.triangles.size(), false);
    for (uint32_t t : world.trianglesOfFaces(baked.replacedFaces[heaviest])) mine[t] = true;
    const RenderGeometry heldOne = subset(view, without(pvs, mine));
    // Frames that see this impostor, their references marked by its faces.
    std::vector<Camera> views;
    std::vector<Reference> viewRefs;
    for (const Camera& c : cameras) {
      const Camera towards = facing(c, site.box.center());
      views.push_back(towards);
      viewRefs.push_back(reference(all, *rays, mine, towards, a.supersample));
    }
    ProgressBar bar("sweep", sweepRows(bake).size());
    for (const SweepRow& row : sweepRows(bake)) {
      ImpostorStats stats;
      auto one = std::make_shared<ImpostorSet>();
      one->cell = cell;
      one->impostors.push_back(std::make_shared<const Impostor>(
          bakeImpostor(view, cell, site.box, site.triangles, row.options, &stats)));
      one->expected = 1;
      PipelineOptions po = pipelineOptions(RenderMode::Pipeline, d);
      po.splat = row.splat;
      FrameRenderer r(heldOne, po);
      r.setImpostors(one);
      const ModeResult m = runMode("impostor", r, views, viewRefs, false);
      const size_t rowHoles = holes(one->impostors, views, viewRefs, row.splat);
      sweep.push_back({{"knob", row.knob},
                       {"value", row.value},
                       {"points", stats.points},
                       {"points_per_pixel", stats.pointsPerPixel},
                       {"bytes", stats.bytes},
                       {"bake_s", stats.seconds},
                       {"footprint_mae", m.error.footMae()},
                       {"footprint_rmse", m.error.footRmse()},
                       {"footprint_wrong_share", m.error.footWrongShare()},
                       {"outline_mae", m.error.outlineMae()},
                       {"inside_mae", m.error.insideMae()},
                       {"holes", rowHoles},
                       {"median_frame_ms", medianOf(m.ms)}});
      bar.advance();
    }
    bar.finish();
  }

  json impostors = json::array();
  for (size_t i = 0; i < baked.impostors.size(); ++i) {
    const ImpostorSite& site = baked.placement.sites[baked.siteOf[i]];
    const ImpostorStats& s = baked.stats[i];
    impostors.push_back({{"sector", site.sector},
                         {"band", site.band},
                         {"triangles", site.triangles.size()},
                         {"points", s.points},
                         {"points_per_pixel", s.pointsPerPixel},
                         {"bytes", s.bytes},
                         {"geometry_bytes", baked.geometryBytes[i]},
                         {"bake_s", s.seconds},
                         {"splat_ms", splatMs[i]},
                         {"splat_fps", splatMs[i] > 0 ? 1000.0 / splatMs[i] : 0.0}});
    if (a.gl) {
      impostors.back()["gl_ms"] = glMs[i];
      impostors.back()["gl_fps"] = glMs[i] > 0 ? 1000.0 / glMs[i] : 0.0;
    }
  }
  size_t footprint = 0;
  for (const Reference& r : refs) footprint += r.footprintPixels;
  const size_t footprintHoles = holes(set->impostors, cameras, refs, PointSplat{});
  json modesJson = json::array();
  for (const ModeResult& m : modes) {
    modesJson.push_back(errorJson(m));
    modesJson.back()["frame_ms_vs_ray_cast"] = medianRatio(m, modes[kRayCast]);
    modesJson.back()["frame_ms_vs_ray_cast_splatted"] = medianRatio(m, modes[kRayCast], &modes[0]);
    modesJson.back()["median_stage_ms_splatted"] = medianStages(m, &modes[0]);
    modesJson.back()["mean_frame_ms"] =
        std::accumulate(m.ms.begin(), m.ms.end(), 0.0) / double(std::max<size_t>(1, m.ms.size()));
  }
  if (a.json) {
    std::cout << json{{"scene", scene.name},
                      {"cell", a.cell},
                      {"frames", cameras.size()},
                      {"repeats", a.repeats},
                      {"size", a.size},
                      {"supersample", a.supersample},
                      {"footprint_pixels", footprint},
                      {"holes", footprintHoles},
                      {"impostor_bytes", impostorBytes},
                      {"geometry_bytes", geometryBytes},
                      {"impostors", impostors},
                      {"modes", modesJson},
                      {"sweep", sweep}}
                     .dump()
              << "\n";
    return 0;
  }
  fmt::print("{} cell {}: {} impostors ({} bytes; the faces they replace: {} bytes as geometry)\n",
             scene.name, a.cell, baked.impostors.size(), impostorBytes, geometryBytes);
  fmt::print(
      "walk of {} frames at {}, reference {}x{} rays a pixel; footprint {} pixels, {} holes\n\n",
      cameras.size(), a.size, a.supersample, a.supersample, footprint, footprintHoles);
  fmt::print("  {:<10} {:>13} {:>14} {:>16} {:>11} {:>10} {:>10} {:>9} {:>12} {:>12}\n",
             "far field", "footprint MAE", "footprint RMSE", "off > 32 levels", "outline MAE",
             "inside MAE", "frame MAE", "frame ms", "vs ray-cast", "(splatted)");
  for (const ModeResult& m : modes)
    fmt::print(
        "  {:<10} {:>13.2f} {:>14.2f} {:>15.1f}% {:>11.2f} {:>10.2f} {:>10.2f} {:>9.2f} "
        "{:>11.3f}x {:>11.3f}x\n",
        m.name, m.error.footMae(), m.error.footRmse(), 100.0 * m.error.footWrongShare(),
        m.error.outlineMae(), m.error.insideMae(), m.error.frameMae(), medianOf(m.ms),
        medianRatio(m, modes[kRayCast]), medianRatio(m, modes[kRayCast], &modes[0]));
  fmt::print(
      "  (frame ms: median over {} frames x {} walks, the modes interleaved frame by frame; "
      "vs ray-cast: median of the per-frame ratios, over every frame and over the {} where the "
      "impostors were splatted)\n",
      cameras.size(), a.repeats,
      std::count(modes[0].splatted.begin(), modes[0].splatted.end(), uint8_t(1)));
  fmt::print("\n  {:>6} {:>4} {:>9} {:>9} {:>7} {:>9} {:>10} {:>8} {:>9} {:>9}{}\n", "sector",
             "band", "triangles", "points", "pts/px", "bytes", "geometry B", "bake s", "splat ms",
             "splat fps", a.gl ? fmt::format(" {:>8} {:>8}", "GL ms", "GL fps") : "");
  for (const json& i : impostors)
    fmt::print("  {:>6} {:>4} {:>9} {:>9} {:>7.2f} {:>9} {:>10} {:>8.2f} {:>9.2f} {:>9.0f}{}\n",
               i["sector"].get<int>(), i["band"].get<int>(), i["triangles"].get<size_t>(),
               i["points"].get<size_t>(), i["points_per_pixel"].get<double>(),
               i["bytes"].get<size_t>(), i["geometry_bytes"].get<size_t>(),
               i["bake_s"].get<double>(), i["splat_ms"].get<double>(), i["splat_fps"].get<double>(),
               a.gl ? fmt::format(" {:>8.2f} {:>8.0f}", i["gl_ms"].get<double>(),
                                  i["gl_fps"].get<double>())
                    : "");
  if (!sweep.empty()) {
    fmt::print("\n  knob sweep on the heaviest impostor (error on its footprint):\n");
    fmt::print("  {:<10} {:>6} {:>8} {:>7} {:>9} {:>7} {:>6} {:>7} {:>8} {:>7} {:>6} {:>9}\n",
               "knob", "value", "points", "pts/px", "bytes", "bake s", "MAE", "RMSE", "outline",
               "inside", "holes", "frame ms");
    for (const json& r : sweep)
      fmt::print(
          "  {:<10} {:>6} {:>8} {:>7.2f} {:>9} {:>7.2f} {:>6.2f} {:>7.2f} {:>8.2f} {:>7.2f} {:>6} "
          "{:>9.2f}\n",
          r["knob"].get<std::string>(), r["value"].get<std::string>(), r["points"].get<size_t>(),
          r["points_per_pixel"].get<double>(), r["bytes"].get<size_t>(), r["bake_s"].get<double>(),
          r["footprint_mae"].get<double>(), r["footprint_rmse"].get<double>(),
          r["outline_mae"].get<double>(), r["inside_mae"].get<double>(), r["holes"].get<size_t>(),
          r["median_frame_ms"].get<double>());
  }
  return 0;
}

}  // namespace
}  // namespace vistream

int main(int argc, char** argv) {
  using namespace vistream;
  Args a;
  std::string logLevel = "warn";
  CLI::App app(
      "Image error of point-based impostors against a supersampled ray-cast reference, beside "
      "raw far-field geometry and the ray-cast far field, along a walk through one view cell");
  showDefaultsInHelp(app);
  app.add_option("--scene", a.scene, "scene: a built-in name, a file or a manifest");
  app.add_option("--cell", a.cell, "the view cell x0,y0,z0,x1,y1,z1 (file coordinates)");
  app.add_option("--frames", a.frames, "frames of the walk")->check(inRange<size_t>(1, 1000));
  app.add_option("--repeats", a.repeats,
                 "walks of the same frames in every mode, for more frame-time samples")
      ->check(inRange<size_t>(1, 100));
  app.add_option("--size", a.size, "frame size WxH");
  app.add_option("--supersample", a.supersample, "reference rays a pixel per axis")
      ->check(inRange(1, 8));
  app.add_option("--near-distance", a.placement.nearDistance, "d: the client's near field (m)")
      ->check(positive());
  app.add_option("--min-triangles", a.placement.minTriangles,
                 "a sector-band with fewer triangles stays geometry")
      ->check(atLeast<size_t>(1));
  app.add_option("--max-bytes-ratio", a.placement.maxBytesRatio,
                 "impostors costlier than this many times their geometry stay geometry (0: no "
                 "limit)")
      ->check(nonNegative());
  app.add_option("--png", a.png,
                 "write the crops (reference, impostors, geometry, ray-cast, "
                 "held-only) of the frame that sees most of the impostors");
  app.add_flag("--sweep", a.sweep, "sweep the bake's knobs on the heaviest impostor");
  app.add_flag("--gl", a.gl,
               "also time each impostor drawn by the OpenGL point shader (needs a display)");
  app.add_option("--lighting-cache", a.lightingCache, "where baked lighting is kept");
  app.add_flag("--json", a.json, "one JSON object instead of tables");
  app.add_option("--log-level", logLevel, "trace, debug, info, warn, error, critical, off");
  return runFlatToolApp("bench_impostor_image", app, argc, argv, logLevel, [&] { return run(a); });
}
