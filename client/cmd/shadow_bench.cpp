#include "client/cmd/shadow_bench.h"

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numbers>
#include <vector>

#include "client/farfield/pipeline.h"
#include "client/render/image.h"
#include "client/render/render_geometry.h"
#include "common/avatar/avatar_model.h"
#include "common/avatar/self_shadow.h"
#include "common/avatar/skinning.h"
#include "common/core/error.h"
#include "common/core/median.h"
#include "common/core/progress.h"
#include "common/core/timer.h"
#include "common/generate/generate.h"
#include "common/light/environment_light.h"
#include "common/light/spherical_harmonics.h"
#include "common/light/texture.h"
#include "common/scene/scene_loader.h"

namespace vistream {
namespace {

using json = nlohmann::json;

struct Model {
  Scene scene;
  SkinnedMesh mesh;
  std::vector<glm::uvec3> coarse;  // the welded model before subdivision
  TriangleGroups groups;           // of mesh.triangles, for culling
  int levels = 0, split = 4;
  const Animation* clip = nullptr;
  std::vector<float> times;  // of the benchmark's frames
};

// One knob setting's run over every frame.
struct Run {
  std::string knob, value;
  SelfShadowOptions options;
  int ring = 0;  // mesh hierarchy: 0 off, else the fine ring
  double msPerFrame = 0, transformMs = 0, rasterMs = 0, integrateMs = 0;
  double l2 = 0;  // against the reference, over its frames
  double blockersPerVertex = 0;
};

// The converged Monte Carlo reference. On large models it is traced for a
// fixed sample of the vertices only (every error is then measured over the
// sample): converging all of them would take minutes a frame.
struct Reference {
  std::vector<std::vector<float>> transfer;  // per reference frame
  std::vector<size_t> frames;                // their indices into Model::times
  std::vector<uint8_t> sample;               // the vertices traced (all ones: every vertex)
  size_t sampled = 0;
  // Its own error (mean relative L2), from the difference of its two
  // independent halves: each half has sqrt(2) times the whole's error, so
  // their difference has about twice it.
  double ownError = 0.0;
};

// Where both selections hold (a null one selects every vertex).
std::vector<uint8_t> both(const std::vector<uint8_t>& a, const std::vector<uint8_t>* b) {
  std::vector<uint8_t> out = a;
  if (b)
    for (size_t v = 0; v < out.size(); ++v) out[v] = out[v] && (*b)[v];
  return out;
}

// The direction the figure's camera looks along (renderTransfer), for the
// front-facing knob.
Camera figureCamera() {
  Camera camera;
  camera.width = camera.height = 320;
  camera.vfovDeg = 40.0f;
  camera.yawDeg = 55.0f;
  camera.pitchDeg = -12.0f;
  return camera;
}

// Keeps the vertices `only` selects (all without it) of transfer vectors of
// `terms` coefficients.
std::vector<float> selected(const std::vector<float>& t, int terms,
                            const std::vector<uint8_t>* only) {
  if (!only) return t;
  std::vector<float> out;
  for (size_t v = 0; v < only->size(); ++v)
    if ((*only)[v])
      out.insert(out.end(), t.begin() + std::ptrdiff_t(v * size_t(terms)),
                 t.begin() + std::ptrdiff_t((v + 1) * size_t(terms)));
  return out;
}

// frontOnly: shade only the vertices of triangles facing the figure's
// camera, as the paper does; the error is then over those vertices.
Run runOnce(const Model& m, const SelfShadowOptions& options, int ring, const Reference& reference,
            const VertexBlockers* pvs = nullptr, bool frontOnly = false) {
  Run r;
  r.options = options;
  r.ring = ring;
  const SelfShadowing shadows(options);
  const ShadowHierarchy hierarchy =
      ring > 0 && !pvs ? ShadowHierarchy::build(m.mesh.triangles, m.coarse, m.levels, ring,
                                                m.mesh.positions.size(), m.split)
                       : ShadowHierarchy{};
  std::vector<double> total, transform, raster, integrate;
  double l2 = 0, blockers = 0;
  PosedMesh pose;
  std::vector<float> out;
  for (size_t f = 0; f < m.times.size(); ++f) {
    Stopwatch clock;
    poseAt(m.scene, m.mesh, m.clip, m.times[f], pose);
    std::vector<uint8_t> front;
    if (frontOnly)
      front = frontFacingVertices(pose.positions, m.mesh.triangles, figureCamera().forward());
    const std::vector<uint8_t>* only = frontOnly ? &front : nullptr;
    const double transformMs = clock.ms();
    SelfShadowStats stats;
    out.clear();  // `only` would keep the last frame's other vertices
    if (pvs)
      shadows.diffuse(pose.positions, pose.normals, *pvs, out, {.stats = &stats, .only = only});
    else
      shadows.diffuse(pose.positions, pose.normals, m.mesh.triangles, out,
                      {.stats = &stats,
                       .hierarchy = ring > 0 ? &hierarchy : nullptr,
                       .groups = &m.groups,
                       .only = only});
    const double frameMs = clock.ms();
    total.push_back(frameMs);
    transform.push_back(transformMs);
    // Thread seconds split the shadow time between its two parts.
    const double threadSeconds = std::max(1e-12, stats.rasterSeconds + stats.integrateSeconds);
    raster.push_back((frameMs - transformMs) * stats.rasterSeconds / threadSeconds);
    integrate.push_back((frameMs - transformMs) * stats.integrateSeconds / threadSeconds);
    blockers += double(stats.rasterized) / double(std::max<uint64_t>(1, stats.vertices));
    const auto at = std::find(reference.frames.begin(), reference.frames.end(), f);
    if (at != reference.frames.end()) {
      // Fewer SH terms than the reference's count as zeros for the rest.
      const int full = shTerms(TransferOptions{}.orders), terms = shadows.terms();
      std::vector<float> padded(pose.positions.size() * size_t(full), 0.0f);
      for (size_t v = 0; v < pose.positions.size(); ++v)
        std::copy_n(out.begin() + std::ptrdiff_t(v * size_t(terms)), terms,
                    padded.begin() + std::ptrdiff_t(v * size_t(full)));
      const std::vector<uint8_t> measured = both(reference.sample, only);
      l2 += meanRelativeL2(
          selected(padded, full, &measured),
          selected(reference.transfer[size_t(at - reference.frames.begin())], full, &measured),
          full);
    }
  }
  r.msPerFrame = median(total);
  r.transformMs = median(transform);
  r.rasterMs = median(raster);
  r.integrateMs = median(integrate);
  r.l2 = reference.frames.empty() ? 0.0 : l2 / double(reference.frames.size());
  r.blockersPerVertex = blockers / double(m.times.size());
  return r;
}

json runJson(const Run& r) {
  return {{"knob", r.knob},
          {"value", r.value},
          {"ms_per_frame", r.msPerFrame},
          {"fps", r.msPerFrame > 0 ? 1000.0 / r.msPerFrame : 0.0},
          {"l2_error", r.l2},
          {"blockers_per_vertex", r.blockersPerVertex}};
}

// One view of the posed model, each vertex coloured by albedo / pi times
// the environment's light through its transfer vector, scaled by `exposure`.
ImageRgb8 renderTransfer(const PosedMesh& pose, const std::vector<glm::uvec3>& triangles,
                         const std::vector<float>& transfer, int orders,
                         const EnvironmentLight& light, const glm::vec3& albedo, float exposure) {
  const int terms = shTerms(orders);
  RenderGeometry g;
  g.sky = {40, 40, 48};
  g.haze = Haze{};
  g.triangles = flattenMesh(pose.positions, triangles);
  for (const glm::vec3& p : g.triangles.positions) g.bounds.extend(p);
  for (size_t t = 0; t < triangles.size(); ++t) {
    glm::u8vec3 corners[3];
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = triangles[t][k];
      const glm::vec3 radiance =
          light.transferred(transfer.data() + size_t(v) * size_t(terms), orders);
      corners[k] = encodeColour(albedo / std::numbers::pi_v<float> * radiance * exposure);
    }
    g.lighting.append(1, corners, 3);
  }
  Camera camera = figureCamera();
  const glm::vec3 centre = g.bounds.center();
  const float radius = 0.5f * glm::length(g.bounds.hi - g.bounds.lo);
  const float distance = 1.05f * radius / std::tan(glm::radians(0.5f * camera.vfovDeg));
  camera.eye = centre - camera.forward() * distance;
  camera.zNear = 0.01f * radius;
  PipelineOptions options;
  options.mode = RenderMode::GeometryAll;
  FrameRenderer renderer(g, options);
  ImageRgb8 image(camera.width, camera.height);
  renderer.render(camera, image);
  return image;
}

// The three views of issue 15's figure for one pose: no shadows, ours,
// Monte Carlo.
void writeShadowPng(const std::string& file, const std::string& environment, const Model& m,
                    size_t frame, const std::vector<float>& reference, int orders) {
  PosedMesh pose;
  poseAt(m.scene, m.mesh, m.clip, m.times[frame], pose);
  const EnvironmentLight light = environment.empty() ? EnvironmentLight::of(m.scene.environment)
                                                     : EnvironmentLight::fromHdr(environment);
  std::vector<std::string> warnings;
  const auto textures = loadMaterialTextures(m.scene, warnings);
  glm::vec3 albedo = m.scene.materials.empty() ? glm::vec3(0.8f) : m.scene.materials[0].diffuse;
  if (!textures.empty() && textures[0]) albedo *= textures[0]->mean();
  const SelfShadowing shadows;
  std::vector<float> open, ours;
  shadows.diffuse(pose.positions, pose.normals, std::vector<glm::uvec3>{}, open);  // no blockers
  shadows.diffuse(pose.positions, pose.normals, m.mesh.triangles, ours);
  // One exposure for all three: the brightest unshadowed vertex at 0.75.
  float brightest = 1e-6f;
  for (size_t v = 0; v < pose.positions.size(); ++v)
    brightest = std::max(brightest, glm::dot(albedo * light.transferred(&open[v * 25], orders),
                                             glm::vec3(0.2126f, 0.7152f, 0.0722f)));
  const float exposure = 0.75f * 3.14159265f / brightest;
  const std::vector<ImageRgb8> tiles = {
      renderTransfer(pose, m.mesh.triangles, open, orders, light, albedo, exposure),
      renderTransfer(pose, m.mesh.triangles, ours, orders, light, albedo, exposure),
      renderTransfer(pose, m.mesh.triangles, reference, orders, light, albedo, exposure)};
  writePng(contactSheet(tiles, 3), file);
}

// Monte Carlo's time at error e from its sweep `curve` of (ms, error),
// rays increasing: log-log interpolation, or the nearest end extended with
// error ~ rays^-1/2 (time ~ e^-2).
double msAtError(const std::vector<std::pair<double, double>>& curve, double e) {
  if (e <= 0.0 || curve.empty()) return double(INFINITY);
  for (size_t s = 0; s + 1 < curve.size(); ++s) {
    const auto [t0, e0] = curve[s];
    const auto [t1, e1] = curve[s + 1];
    if (e <= e0 && e >= e1 && e0 > e1) {
      const double x = std::log(e0 / e) / std::log(e0 / e1);
      return std::exp(std::log(t0) + x * std::log(t1 / t0));
    }
  }
  if (e > curve.front().second)
    return curve.front().first * std::pow(curve.front().second / e, 2.0);
  return curve.back().first * std::pow(curve.back().second / e, 2.0);
}

// A converged reference traced as two independent halves:
// traceHalf(h, out) traces half h (0 or 1) with its own seed. Returns their
// mean and appends its own error, error(half 0, half 1) / 2, to ownErrors
// (each half has sqrt 2 times the mean's error, their difference twice it).
template <class TraceHalf, class Error>
std::vector<float> referenceOfHalves(TraceHalf&& traceHalf, Error&& error,
                                     std::vector<double>& ownErrors) {
  std::vector<float> half[2];
  for (int h = 0; h < 2; ++h) traceHalf(h, half[h]);
  ownErrors.push_back(0.5 * error(half[0], half[1]));
  std::vector<float> mean(half[0].size());
  for (size_t i = 0; i < mean.size(); ++i) mean[i] = 0.5f * (half[0][i] + half[1][i]);
  return mean;
}

// |a - b| / |b| over all the vertices' coefficients together. The glossy
// rows use it instead of the per-vertex mean: a vertex whose lobe is almost
// wholly blocked has a reference near zero, and its relative error would
// outweigh every other vertex's.
double fieldRelativeL2(const std::vector<float>& a, const std::vector<float>& b) {
  double num = 0.0, den = 0.0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) {
    num += (double(a[i]) - b[i]) * (double(a[i]) - b[i]);
    den += double(b[i]) * b[i];
  }
  return den > 0.0 ? std::sqrt(num / den) : 0.0;
}

// The glossy rows: a normalized Phong lobe about each front-facing vertex's
// reflection of a viewer at the figure's camera (3 model radii away),
// integrated from the visibility masks the diffuse pass makes, against a
// Monte Carlo reference of its own (`referenceRays`, two halves) and a Monte
// Carlo sweep, on the reference frames and over the reference's sample of
// the vertices that face the viewer. Errors are fieldRelativeL2.
struct GlossyRows {
  float exponent = 0.0f;
  double masksMs = 0.0;      // the diffuse pass of the facing vertices, keeping their masks
  double integrateMs = 0.0;  // the glossy integration of the facing vertices, per pixel
  double l2 = 0.0;           // against the reference
  double blocksMs = 0.0, blocksL2 = 0.0;  // the same in the paper's 4 x 4 blocks
  double referenceError = 0.0;
  size_t facing = 0;  // vertices facing the viewer (first reference frame)
  std::vector<uint32_t> sweep;
  std::vector<std::pair<double, double>> mc;  // (ms, error) per sweep count
  double mcEqualMs() const { return msAtError(mc, l2); }
  double ms() const { return masksMs + integrateMs; }
};

GlossyRows glossyRows(const Model& m, const Reference& reference, int ring, float exponent,
                      uint32_t referenceRays, const std::vector<uint32_t>& sweep) {
  GlossyRows g;
  g.exponent = exponent;
  g.sweep = sweep;
  const SelfShadowing shadows;
  const int orders = TransferOptions{}.orders, terms = shTerms(orders);
  const TransferIntegrator perPixel(shadows.options().maskSide, {orders, false}),
      blocks(shadows.options().maskSide, {orders, true});
  const ShadowHierarchy hierarchy =
      ring > 0 ? ShadowHierarchy::build(m.mesh.triangles, m.coarse, m.levels, ring,
                                        m.mesh.positions.size(), m.split)
               : ShadowHierarchy{};
  std::vector<double> masksMs, integrateMs, l2, blocksMs, blocksL2, own;
  std::vector<std::vector<double>> ms(sweep.size()), err(sweep.size());
  ProgressBar bar("glossy", uint64_t(reference.frames.size()) * (3 + sweep.size()));
  for (const size_t f : reference.frames) {
    PosedMesh pose;
    poseAt(m.scene, m.mesh, m.clip, m.times[f], pose);
    const size_t vertices = pose.positions.size();
    Box3f bounds;
    for (const glm::vec3& p : pose.positions) bounds.extend(p);
    const glm::vec3 eye =
        bounds.center() - figureCamera().forward() * 1.5f * glm::length(bounds.hi - bounds.lo);
    std::vector<glm::vec3> reflected(vertices);
    std::vector<uint8_t> facing(vertices, 0);
    for (size_t v = 0; v < vertices; ++v) {
      const glm::vec3 n = pose.normals[v], toEye = glm::normalize(eye - pose.positions[v]);
      const float c = glm::dot(n, toEye);
      facing[v] = c > 0.0f;
      reflected[v] = 2.0f * c * n - toEye;
    }
    if (g.facing == 0) g.facing = size_t(std::count(facing.begin(), facing.end(), 1));
    const std::vector<uint8_t> measured = both(reference.sample, &facing);
    // The reference, as two independent halves.
    const std::vector<float> ref = referenceOfHalves(
        [&](int h, std::vector<float>& half) {
          monteCarloGlossyTransfer(pose.positions, pose.normals, m.mesh.triangles, reflected,
                                   exponent, referenceRays / 2, orders, half, uint64_t(2 * h + 5),
                                   &measured);
          bar.advance();
        },
        [&](const std::vector<float>& a, const std::vector<float>& b) {
          return fieldRelativeL2(selected(a, terms, &measured), selected(b, terms, &measured));
        },
        own);
    // Ours: the masks of the facing vertices (as the diffuse pass makes
    // them), then the lobe.
    Stopwatch clock;
    std::vector<float> diffuse;
    std::vector<uint64_t> masks;
    shadows.diffuse(pose.positions, pose.normals, m.mesh.triangles, diffuse,
                    {.hierarchy = ring > 0 ? &hierarchy : nullptr,
                     .groups = &m.groups,
                     .only = &facing,
                     .masks = &masks});
    masksMs.push_back(clock.ms());
    const size_t words = size_t(shadows.maskWords());
    for (const TransferIntegrator* integrator : {&perPixel, &blocks}) {
      Stopwatch integrateClock;
      std::vector<float> ours(vertices * size_t(terms), 0.0f);
      tbb::parallel_for(tbb::blocked_range<size_t>(0, vertices, 64), [&](const auto& range) {
        VisibilityMask mask(shadows.options().maskSide);
        for (size_t v = range.begin(); v != range.end(); ++v) {
          if (!facing[v]) continue;
          std::copy_n(masks.data() + v * words, words, mask.data());
          integrator->glossy(mask, TangentFrame::around(pose.normals[v]), reflected[v], exponent,
                             ours.data() + v * size_t(terms));
        }
      });
      (integrator == &perPixel ? integrateMs : blocksMs).push_back(integrateClock.ms());
      (integrator == &perPixel ? l2 : blocksL2)
          .push_back(
              fieldRelativeL2(selected(ours, terms, &measured), selected(ref, terms, &measured)));
    }
    bar.advance();
    for (size_t s = 0; s < sweep.size(); ++s) {
      std::vector<float> estimate;
      Stopwatch mcClock;
      monteCarloGlossyTransfer(pose.positions, pose.normals, m.mesh.triangles, reflected, exponent,
                               sweep[s], orders, estimate, 2, &facing);
      ms[s].push_back(mcClock.ms());
      err[s].push_back(
          fieldRelativeL2(selected(estimate, terms, &measured), selected(ref, terms, &measured)));
      bar.advance();
    }
  }
  bar.finish();
  g.masksMs = median(masksMs);
  g.integrateMs = median(integrateMs);
  g.l2 = median(l2);
  g.blocksMs = median(blocksMs);
  g.blocksL2 = median(blocksL2);
  g.referenceError = median(own);
  for (size_t s = 0; s < sweep.size(); ++s) g.mc.emplace_back(median(ms[s]), median(err[s]));
  return g;
}

}  // namespace

int runShadowBench(const ShadowBenchArgs& a) {
  if (a.model.empty()) throwInputError("--shadows needs --model (a skinned glTF, e.g. Fox.glb)");
  if (a.subdivide < 0 || a.subdivide > 4)
    throwInputError("--subdivide {}: must be 0..4 (each pass quadruples the triangles)",
                    a.subdivide);
  if (!a.environment.empty() && !std::filesystem::exists(a.environment))
    throwInputError("{}: no such file (--environment)", a.environment);
  Model m;
  m.scene = a.model == "walker" && !std::filesystem::exists(a.model) ? generateWalker()
                                                                     : loadScene(a.model);
  if (m.scene.animations.empty())
    throwInputError("{}: has no animation to play (the benchmark poses its first clip)", a.model);
  m.clip = &m.scene.animations.front();
  m.mesh = SkinnedMesh::firstOf(m.scene);
  // Welded (shared corners get one smooth normal), then subdivided; the
  // welded model is the hierarchy's coarse level.
  m.coarse = m.mesh.subdivided(0).triangles;
  m.mesh = m.mesh.subdivided(a.subdivide, SkinnedMesh::Split(a.subdivideBy));
  m.levels = a.subdivide;
  m.split = a.subdivideBy;
  m.groups = TriangleGroups::build(m.mesh.triangles, m.mesh.positions);
  const int frames = std::max(2, a.frames);
  for (int f = 0; f < frames; ++f) m.times.push_back(m.clip->duration * float(f) / float(frames));

  // The reference and the Monte Carlo sweep, on the first frames. The
  // reference traces 65,536 rays a vertex, 4 times the sweep's largest
  // count (half its error), as two independent halves; above 2,000 vertices
  // it traces a sample of 1,000 vertices, evenly spread over the vertex
  // order (which runs from the coarse model's vertices to the finest
  // level's). The sweep traces every vertex (its times are whole frames').
  const size_t vertices = m.mesh.positions.size();
  const bool small = vertices <= 2000;
  const std::vector<uint32_t> sweep =
      a.quick ? std::vector<uint32_t>{64, 256} : std::vector<uint32_t>{64, 256, 1024, 4096, 16384};
  const uint32_t referenceRays = a.quick ? 4 * sweep.back() : 65536;
  Reference reference;
  reference.sample.assign(vertices, small ? 1 : 0);
  if (!small)
    for (size_t k = 0; k < 1000; ++k) reference.sample[k * vertices / 1000] = 1;
  reference.sampled = size_t(std::count(reference.sample.begin(), reference.sample.end(), 1));
  const int orders = TransferOptions{}.orders;
  const int terms = shTerms(orders);
  std::vector<std::pair<double, double>> mc;  // (ms per frame, error)
  {
    ProgressBar bar("monte carlo", uint64_t(a.referenceFrames) * (2 + sweep.size()));
    std::vector<std::vector<double>> ms(sweep.size()), err(sweep.size());
    std::vector<double> ownErrors;
    for (int k = 0; k < std::min(a.referenceFrames, frames); ++k) {
      const size_t f = size_t(k) * size_t(frames) / size_t(std::max(1, a.referenceFrames));
      PosedMesh pose;
      poseAt(m.scene, m.mesh, m.clip, m.times[f], pose);
      const std::vector<float> ref = referenceOfHalves(
          [&](int h, std::vector<float>& half) {
            monteCarloTransfer(pose.positions, pose.normals, m.mesh.triangles, referenceRays / 2,
                               orders, half, uint64_t(2 * h + 1), &reference.sample);
            bar.advance();
          },
          [&](const std::vector<float>& first, const std::vector<float>& second) {
            return meanRelativeL2(selected(first, terms, &reference.sample),
                                  selected(second, terms, &reference.sample), terms);
          },
          ownErrors);
      for (size_t s = 0; s < sweep.size(); ++s) {
        std::vector<float> estimate;
        Stopwatch clock;
        monteCarloTransfer(pose.positions, pose.normals, m.mesh.triangles, sweep[s], orders,
                           estimate, 2);
        ms[s].push_back(clock.ms());
        err[s].push_back(meanRelativeL2(selected(estimate, terms, &reference.sample),
                                        selected(ref, terms, &reference.sample), terms));
        bar.advance();
      }
      reference.frames.push_back(f);
      reference.transfer.push_back(std::move(ref));
    }
    bar.finish();
    reference.ownError = median(ownErrors);
    for (size_t s = 0; s < sweep.size(); ++s) mc.emplace_back(median(ms[s]), median(err[s]));
  }
  if (!a.png.empty() && !reference.frames.empty()) {
    // The picture needs every vertex: a sampled reference is traced again,
    // whole, at the sweep's largest count.
    std::vector<float> whole = reference.transfer.front();
    if (reference.sampled < vertices) {
      PosedMesh pose;
      poseAt(m.scene, m.mesh, m.clip, m.times[reference.frames.front()], pose);
      monteCarloTransfer(pose.positions, pose.normals, m.mesh.triangles, sweep.back(), orders,
                         whole, 1);
    }
    writeShadowPng(a.png, a.environment, m, reference.frames.front(), whole, orders);
  }
  auto mcMsAt = [&](double e) { return msAtError(mc, e); };

  // Defaults, then each knob alone.
  std::vector<Run> runs;
  // The hierarchy is on (two rings) wherever there is a finer level.
  const int defaultRing = a.subdivide > 0 ? 2 : 0;
  auto add = [&](std::string knob, std::string value, SelfShadowOptions o, int ring) {
    Run r = runOnce(m, o, ring, reference);
    r.knob = std::move(knob);
    r.value = std::move(value);
    runs.push_back(std::move(r));
  };
  ProgressBar bar("knobs", a.quick ? 8 : 14);
  add("defaults",
      defaultRing ? "mask 32, table 128, 25 terms, per pixel, ring 2"
                  : "mask 32, table 128, 25 terms, per pixel",
      {}, defaultRing);
  bar.advance();
  // The per-vertex PVS (section 3.2), from poses of the clip between the
  // benchmark's frames (twice as many, a quarter step off), so the error it
  // costs between its poses shows.
  Stopwatch pvsClock;
  std::vector<PosedMesh> pvsPoses(size_t(2 * frames));
  for (size_t k = 0; k < pvsPoses.size(); ++k)
    poseAt(m.scene, m.mesh, m.clip, m.clip->duration * (float(k) + 0.25f) / float(pvsPoses.size()),
           pvsPoses[k]);
  VertexBlockers candidates =
      defaultRing ? VertexBlockers::of(
                        ShadowHierarchy::build(m.mesh.triangles, m.coarse, m.levels, defaultRing,
                                               m.mesh.positions.size(), m.split),
                        m.mesh.triangles)
                  : VertexBlockers::everyTriangle(m.mesh.triangles, m.mesh.positions.size());
  candidates.groupTriangles(m.mesh.positions);
  const VertexBlockers pvs = potentiallyVisibleBlockers(candidates, pvsPoses);
  const double pvsBuildS = pvsClock.ms() / 1000.0;
  {
    Run r = runOnce(m, {}, defaultRing, reference, &pvs);
    r.knob = "per-vertex PVS";
    r.value = fmt::format("on ({} poses, {:.0f} of {:.0f} blockers kept)", pvsPoses.size(),
                          pvs.meanPerVertex(), candidates.meanPerVertex());
    runs.push_back(std::move(r));
  }
  bar.advance();
  for (const int side : a.quick ? std::vector<int>{16} : std::vector<int>{16, 64}) {
    SelfShadowOptions o;
    o.maskSide = side;
    add("mask side", std::to_string(side), o, defaultRing);
    bar.advance();
  }
  for (const int cube : a.quick ? std::vector<int>{64} : std::vector<int>{64, 256}) {
    SelfShadowOptions o;
    o.planeTable = cube;
    add("plane table", std::to_string(cube), o, defaultRing);
    bar.advance();
  }
  if (!a.quick) {
    SelfShadowOptions o;
    o.planeTable = 0;
    add("plane table", "off (exact)", o, defaultRing);
    bar.advance();
  }
  for (const int count : a.quick ? std::vector<int>{9} : std::vector<int>{9, 16}) {
    SelfShadowOptions o;
    o.transfer.orders = int(std::lround(std::sqrt(double(count))));
    add("SH terms", std::to_string(count), o, defaultRing);
    bar.advance();
  }
  {
    SelfShadowOptions o;
    o.transfer.downsample = true;
    add("downsampling", "on (the paper's 4x4)", o, defaultRing);
    bar.advance();
  }
  {
    Run r = runOnce(m, {}, defaultRing, reference, nullptr, true);
    r.knob = "shaded vertices";
    r.value = "front-facing only (the figure's view)";
    runs.push_back(std::move(r));
    bar.advance();
  }
  {
    SelfShadowOptions o;
    o.cullGroups = false;
    add("group culling", defaultRing ? "off (no effect with the hierarchy)" : "off", o,
        defaultRing);
    bar.advance();
  }
  if (defaultRing) {
    add("mesh hierarchy", "ring 1", {}, 1);
    add("mesh hierarchy", "off (every fine triangle)", {}, 0);
  }
  bar.finish();
  const bool glossy = a.glossExponent > 0.0f && !reference.frames.empty();
  const GlossyRows gloss =
      glossy ? glossyRows(m, reference, defaultRing, a.glossExponent, referenceRays, sweep)
             : GlossyRows{};

  const Run& d = runs.front();
  const Run& withPvs = runs[1];
  const double mcEqual = mcMsAt(d.l2), mcEqualPvs = mcMsAt(withPvs.l2);
  const double other = std::max(0.0, d.msPerFrame - d.transformMs - d.rasterMs - d.integrateMs);
  json out = {{"model", a.model},
              {"subdivide", a.subdivide},
              {"subdivide_by", a.subdivideBy},
              {"clip", m.clip->name},
              {"frames", frames},
              {"vertices", m.mesh.positions.size()},
              {"triangles", m.mesh.triangles.size()},
              {"lowres_triangles", a.subdivide > 0 ? m.coarse.size() : 0},
              {"triangle_groups", m.groups.size()},
              {"ms_per_frame", d.msPerFrame},
              {"fps", d.msPerFrame > 0 ? 1000.0 / d.msPerFrame : 0.0},
              {"l2_error", d.l2},
              {"blockers_per_vertex", d.blockersPerVertex},
              {"mc_ms_equal_error", mcEqual},
              {"speedup_vs_mc", mcEqual / d.msPerFrame},
              {"reference_rays", referenceRays},
              {"reference_vertices", reference.sampled},
              {"reference_error", reference.ownError},
              {"breakdown",
               {{"rasterization", d.rasterMs / d.msPerFrame},
                {"integration", d.integrateMs / d.msPerFrame},
                {"transform", d.transformMs / d.msPerFrame},
                {"other", other / d.msPerFrame}}}};
  json mcRows = json::array();
  for (size_t s = 0; s < sweep.size(); ++s)
    mcRows.push_back(
        {{"rays", sweep[s]}, {"ms_per_frame", mc[s].first}, {"l2_error", mc[s].second}});
  out["monte_carlo"] = mcRows;
  out["with_pvs"] = {{"blockers_per_vertex", withPvs.blockersPerVertex},
                     {"candidates_per_vertex", candidates.meanPerVertex()},
                     {"ms_per_frame", withPvs.msPerFrame},
                     {"fps", 1000.0 / withPvs.msPerFrame},
                     {"l2_error", withPvs.l2},
                     {"mc_ms_equal_error", mcEqualPvs},
                     {"speedup_vs_mc", mcEqualPvs / withPvs.msPerFrame},
                     {"poses", pvsPoses.size()},
                     {"build_s", pvsBuildS}};
  json knobRows = json::array();
  for (const Run& r : runs) knobRows.push_back(runJson(r));
  out["knobs"] = knobRows;
  if (glossy) {
    json glossyMc = json::array();
    for (size_t s = 0; s < gloss.sweep.size(); ++s)
      glossyMc.push_back({{"rays", gloss.sweep[s]},
                          {"ms_per_frame", gloss.mc[s].first},
                          {"l2_error", gloss.mc[s].second}});
    out["glossy"] = {{"exponent", gloss.exponent},
                     {"facing_vertices", gloss.facing},
                     {"masks_ms_per_frame", gloss.masksMs},
                     {"integrate_ms_per_frame", gloss.integrateMs},
                     {"ms_per_frame", gloss.ms()},
                     {"l2_error", gloss.l2},
                     {"reference_error", gloss.referenceError},
                     {"mc_ms_equal_error", gloss.mcEqualMs()},
                     {"speedup_vs_mc", gloss.mcEqualMs() / gloss.ms()},
                     {"speedup_vs_mc_integration_only", gloss.mcEqualMs() / gloss.integrateMs},
                     {"blocks",
                      {{"integrate_ms_per_frame", gloss.blocksMs},
                       {"l2_error", gloss.blocksL2},
                       {"mc_ms_equal_error", msAtError(gloss.mc, gloss.blocksL2)}}},
                     {"monte_carlo", glossyMc}};
  }

  if (a.json) {
    std::printf("%s\n", out.dump(2).c_str());
    return 0;
  }
  std::printf("\nself-shadowing of %s (%s clip, %d frames): %zu vertices, %zu triangles\n\n",
              a.model.c_str(), m.clip->name.c_str(), frames, m.mesh.positions.size(),
              m.mesh.triangles.size());
  std::printf("Table 1 (the paper's rows):\n%-28s %10zu\n%-28s %10zu\n%-28s %10s\n", "vertices",
              m.mesh.positions.size(), "triangles", m.mesh.triangles.size(), "low-res triangles",
              a.subdivide > 0 ? std::to_string(m.coarse.size()).c_str() : "-");
  std::printf("%-28s %10.1f\n%-28s %10.1f\n%-28s %10.1f\n%-28s %10.1f\n%-28s %9.2f%%\n",
              "blockers a vertex", d.blockersPerVertex, "blockers a vertex (PVS)",
              withPvs.blockersPerVertex, "fps", 1000.0 / d.msPerFrame, "fps with PVS",
              1000.0 / withPvs.msPerFrame, "L2 error", 100.0 * d.l2);
  std::printf("%-28s %9.2f%%\n%-28s %10.1f\n%-28s %9.1fx\n\n", "L2 error with PVS",
              100.0 * withPvs.l2, "PVS build, s", pvsBuildS, "with PVS, faster than MC",
              mcEqualPvs / withPvs.msPerFrame);
  std::printf(
      "%-28s %10.2f\n%-28s %10.1f\n%-28s %10.4f\n%-28s %10.1f\n%-28s %10.2f\n%-28s %9.1fx\n",
      "ms a frame (median)", d.msPerFrame, "frames a second", 1000.0 / d.msPerFrame,
      "mean relative L2 error", d.l2, "blockers a vertex", d.blockersPerVertex,
      "Monte Carlo ms, same error", mcEqual, "faster than Monte Carlo", mcEqual / d.msPerFrame);
  std::printf(
      "\nTable 2, share of a frame:\n%-28s %9.1f%%\n%-28s %9.1f%%\n%-28s %9.1f%%\n%-28s %9.1f%%\n",
      "rasterization", 100 * d.rasterMs / d.msPerFrame, "integration",
      100 * d.integrateMs / d.msPerFrame, "transform", 100 * d.transformMs / d.msPerFrame, "other",
      100 * other / d.msPerFrame);
  std::printf(
      "\nMonte Carlo (Embree), against %u rays a vertex on %zu of %zu vertices (the reference's "
      "own error: %.2f%%):\n%-10s %12s %12s\n",
      referenceRays, reference.sampled, vertices, 100.0 * reference.ownError, "rays", "ms a frame",
      "L2 error");
  for (size_t s = 0; s < sweep.size(); ++s)
    std::printf("%-10u %12.1f %12.4f\n", sweep[s], mc[s].first, mc[s].second);
  std::printf("\nAccuracy against time, one knob at a time:\n%-16s %-46s %10s %8s %10s %9s\n",
              "knob", "value", "ms/frame", "fps", "L2 error", "blockers");
  for (const Run& r : runs)
    std::printf("%-16s %-46s %10.2f %8.1f %10.4f %9.1f\n", r.knob.c_str(), r.value.c_str(),
                r.msPerFrame, 1000.0 / r.msPerFrame, r.l2, r.blockersPerVertex);
  if (glossy) {
    std::printf(
        "\nGlossy (Phong %g about the figure's viewer, %zu facing vertices; against %u rays a "
        "vertex, own error %.2f%%):\n",
        gloss.exponent, gloss.facing, referenceRays, 100.0 * gloss.referenceError);
    std::printf("%-28s %10.2f\n%-28s %10.2f\n%-28s %9.2f%%\n%-28s %10.1f\n%-28s %9.1fx\n",
                "masks ms a frame", gloss.masksMs, "glossy integration ms", gloss.integrateMs,
                "L2 error", 100.0 * gloss.l2, "Monte Carlo ms, same error", gloss.mcEqualMs(),
                "faster than Monte Carlo", gloss.mcEqualMs() / gloss.ms());
    std::printf("%-28s %9.1fx\n%-28s %10.2f\n%-28s %9.2f%%\n", "  integration alone",
                gloss.mcEqualMs() / gloss.integrateMs, "4x4 blocks: integration ms", gloss.blocksMs,
                "4x4 blocks: L2 error", 100.0 * gloss.blocksL2);
    std::printf("%-10s %12s %12s\n", "rays", "ms a frame", "L2 error");
    for (size_t s = 0; s < gloss.sweep.size(); ++s)
      std::printf("%-10u %12.1f %12.4f\n", gloss.sweep[s], gloss.mc[s].first, gloss.mc[s].second);
  }
  return 0;
}

}  // namespace vistream
