#include "client/farfield/pipeline.h"

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <unordered_map>

#include "common/core/check.h"
#include "common/core/stats_output.h"
#include "common/core/timer.h"

namespace vistream {
namespace {

constexpr size_t kRayChunk = 1024;
constexpr float kGlInsetPx = 0.125f;

// Casts `rays` on TBB in chunks; hits.size() == rays.size().
void castRays(const RayQuery& query, const std::vector<Ray>& rays, std::vector<Hit>& hits) {
  hits.resize(rays.size());
  const size_t chunks = (rays.size() + kRayChunk - 1) / kRayChunk;
  tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
    const size_t begin = c * kRayChunk, count = std::min(kRayChunk, rays.size() - begin);
    query.firstHits(std::span<const Ray>(rays.data() + begin, count),
                    std::span<Hit>(hits.data() + begin, count));
  });
}

}  // namespace

const char* renderModeName(RenderMode m) {
  constexpr std::array<const char*, 4> kNames{"pipeline", "raycast-all", "geometry-all",
                                              "impostor-off"};
  return size_t(m) < kNames.size() ? kNames[size_t(m)] : "?";
}

nlohmann::json FrameReport::toJson() const {
  return {
      {"pixels", statsJson(pixels)},
      {"ms", statsJson(ms)},
      {"near_triangles", nearTriangles},
      {"moving", moving},
      {"stages",
       {{"far_field", {{"ran", farFieldRan}, {"why", farFieldWhy}}},
        {"horizon_tracing", {{"ran", horizonRan}, {"why", horizonWhy}}},
        {"image_cache",
         {{"ran", cacheRan},
          {"why", cacheWhy},
          {"impostor_texels_forgotten", impostorTexelsForgotten}}},
        {"impostors",
         {{"ran", impostorsRan},
          {"why", impostorsWhy},
          {"drawn", impostorsDrawn},
          {"points_on_screen", impostorPoints}}}}},
      {"cache_plan",
       {{"must_trace", cachePlan.mustTrace},
        {"budgeted", cachePlan.budgeted},
        {"edges", cachePlan.edges},
        {"reused", cachePlan.reused},
        {"degraded", cachePlan.degraded}}},
      {"horizon_columns_traced", horizonStats.columnsTraced},
      {"horizon_cells_visited", horizonStats.cellsVisited},
  };
}

FrameRenderer::FrameRenderer(const RenderGeometry& geometry, const PipelineOptions& options)
    : geometry_(geometry), options_(options) {
  grid_ = FieldGrid(geometry, options.gridCellSize);
  horizon_ = HorizonMap(geometry, options.horizonCellSize);
  rays_ = makeBatchedEmbreeRayQuery();
  rays_->addBatch(geometry.triangles, 0, uint32_t(geometry.size()));
  rays_->commit();
  liveTriangles_ = geometry.size();
  // A scene small enough for the polygon budget is drawn whole: the far
  // field would cost more than it saves.
  wholeScene_ = options.polygonBudget > 0 && liveTriangles_ <= options.polygonBudget;
}

namespace {

// Boxes holding triangles [first, end) of `g`, one per X/Z square of
// kChangeBoxSide metres they start in: what the image cache tests its texels
// against (smaller boxes keep more texels; more boxes cost more tests).
constexpr float kChangeBoxSide = 32.0f;

std::vector<Box3f> changeBoxes(const RenderGeometry& g, uint32_t first, uint32_t end) {
  std::unordered_map<uint64_t, Box3f> byCell;
  for (uint32_t t = first; t < end; ++t) {
    const Box3f b = g.triangles.triangleBounds(t);
    if (b.empty()) continue;
    const glm::vec2 c = glm::floor(glm::vec2(b.lo.x, b.lo.z) / kChangeBoxSide);
    const uint64_t key = (uint64_t(uint32_t(int32_t(std::clamp(c.x, -1e9f, 1e9f)))) << 32) |
                         uint32_t(int32_t(std::clamp(c.y, -1e9f, 1e9f)));
    Box3f& box = byCell[key];
    box.extend(b.lo);
    box.extend(b.hi);
  }
  std::vector<Box3f> boxes;
  boxes.reserve(byCell.size());
  for (const auto& [key, box] : byCell) boxes.push_back(box);
  return boxes;
}

}  // namespace

bool FrameRenderer::update(const GeometryChange& change) {
  const RenderGeometry& g = geometry_;
  VS_CHECK_LE(size_t(change.firstAdded), g.size());
  lastUpdate_ = UpdateStats{};
  lastUpdate_.added = g.size() - change.firstAdded;
  lastUpdate_.removed = change.removed.size();
  if (change.empty(g.size())) return true;
  Stopwatch clock;
  const uint32_t count = uint32_t(g.size() - change.firstAdded);
  grid_.remove(g, change.removed);
  if (!grid_.add(g, change.firstAdded, count)) return false;
  lastUpdate_.gridMs = clock.ms();
  clock = Stopwatch();
  rays_->removeTriangles(change.removed);
  rays_->addBatch(g.triangles, change.firstAdded, count);
  rays_->commit();
  lastUpdate_.raysMs = clock.ms();
  clock = Stopwatch();
  if (!horizon_.raise(g, change.firstAdded, count)) {
    // Room to grow: a quarter of the extent on every side.
    Box3f cover = horizon_.extent();
    cover.extend(g.bounds.lo);
    cover.extend(g.bounds.hi);
    const glm::vec3 spare = 0.25f * cover.extent();
    horizon_ = HorizonMap(g, options_.horizonCellSize, Box3f{cover.lo - spare, cover.hi + spare});
    lastUpdate_.horizonRebuilt = true;
  }
  lastUpdate_.horizonMs = clock.ms();
  liveTriangles_ = liveTriangles_ + count - change.removed.size();
  wholeScene_ = options_.polygonBudget > 0 && liveTriangles_ <= options_.polygonBudget;
  if (cache_) {
    std::vector<uint8_t> removed(change.removed.empty() ? 0 : g.size(), 0);
    for (const uint32_t t : change.removed) removed[t] = 1;
    const std::vector<Box3f> boxes = changeBoxes(g, change.firstAdded, uint32_t(g.size()));
    clock = Stopwatch();
    lastUpdate_.texelsForgotten = cache_->invalidate(boxes, removed);
    lastUpdate_.cacheMs = clock.ms();
  }
  return true;
}

FrameRenderer::~FrameRenderer() = default;

void FrameRenderer::reset() {
  cache_.reset();
  cachedImpostors_.reset();
  havePrevious_ = false;
}

float FrameRenderer::polygonDistance() const {
  return isPipeline(options_.mode) && !wholeScene_ ? options_.nearDistance
                                                   : std::numeric_limits<float>::infinity();
}

FrameReport FrameRenderer::render(const Camera& camera, ImageRgb8& out) {
  return run(camera, out, nullptr);
}

FrameReport FrameRenderer::renderFarField(const Camera& camera, ImageRgb8& farImage,
                                          std::vector<uint32_t>& near, GpuImpostors* gpu) {
  return run(camera, farImage, &near, gpu);
}

// One frame of the pipeline as named steps (the thesis's stages 1-7). Built
// and run by FrameRenderer::run; holds the frame's intermediate buffers.
struct FrameRun {
  FrameRenderer& r;
  const Camera& camera;
  ImageRgb8& out;
  std::vector<uint32_t>* glNear;  // OpenGL draws the near field: only its triangles are wanted
  GpuImpostors* gpu;              // OpenGL splats the impostors: their depth limits are wanted
  const int W, H;
  const size_t pixels;
  const RenderMode mode;
  const float d;
  const glm::u8vec3 sky;
  bool turned = false;
  bool wholeScene = false;
  FrameReport rep;
  std::vector<float> slopes;               // per column: the horizon's slope
  std::vector<uint32_t> candidates;        // far-field pixels
  std::vector<uint32_t> skyPixels;         // culled as sky by the horizon of the geometry held
  std::vector<uint32_t> backgroundPixels;  // no polygon, and no far field held to look at
  std::vector<glm::vec3> dirs;             // their ray directions
  std::vector<uint8_t> trace;              // per candidate: cast a ray this frame
  std::vector<int64_t> texels;             // per candidate: its cache texel
  bool useCache = false;
  std::vector<Ray> rays;
  std::vector<uint32_t> rayOf;  // per ray: its candidate
  std::vector<Hit> hits;

  FrameRun(FrameRenderer& renderer, const Camera& c, ImageRgb8& o, std::vector<uint32_t>* gl,
           GpuImpostors* g)
      : r(renderer),
        camera(c),
        out(o),
        glNear(gl),
        gpu(g),
        W(c.width),
        H(c.height),
        pixels(size_t(c.width) * size_t(c.height)),
        mode(renderer.options_.mode),
        d(renderer.options_.nearDistance),
        sky(renderer.geometry_.sky) {}

  void setPixel(size_t p, glm::u8vec3 c) { out.set(int(p % size_t(W)), int(p / size_t(W)), c); }

  // Whether the viewer moved or turned since the previous frame.
  void trackMotion() {
    turned =
        !r.havePrevious_ || camera.yawDeg != r.previousYaw_ || camera.pitchDeg != r.previousPitch_;
    rep.moving = r.havePrevious_ && (glm::length(camera.eye - r.previousEye_) > 1e-3f || turned);
    r.havePrevious_ = true;
    r.previousEye_ = camera.eye;
    r.previousYaw_ = camera.yawDeg;
    r.previousPitch_ = camera.pitchDeg;
    if (out.width != W || out.height != H) out = ImageRgb8(W, H);
    wholeScene = isPipeline(mode) && r.wholeScene_;
  }

  // 1. Near field: the triangles to draw as polygons.
  void selectNearField() {
    Stopwatch clock;
    if (mode == RenderMode::RaycastAll)
      r.near_.clear();
    else
      r.grid_.nearField(camera,
                        mode == RenderMode::GeometryAll || wholeScene
                            ? std::numeric_limits<float>::infinity()
                            : d,
                        r.near_, r.stamp_, r.stampValue_);
    rep.nearTriangles = r.near_.size();
    rep.ms.nearSelect = clock.ms();
  }

  // 2. Polygons and the opacity buffer.
  void drawPolygons() {
    Stopwatch clock;
    const auto& triangles = r.geometry_.triangles;
    r.idsDrawn_ = !glNear;
    if (glNear) {
      *glNear = r.near_;
      r.raster_.coverage(camera, triangles, r.near_, kGlInsetPx, r.covered_, r.polygonDistance());
      rep.ms.opacity = clock.ms();
      return;
    }
    r.raster_.draw(camera, triangles, r.near_, r.ids_, r.polygonDistance());
    rep.ms.nearDraw = clock.ms();
    clock = Stopwatch();
    coverageOf(r.ids_, r.covered_);
    rep.ms.opacity = clock.ms();
  }

  // 3a. What the far field calls for in this frame.
  void decideFarField() {
    const PipelineOptions& options = r.options_;
    if (mode == RenderMode::GeometryAll) {
      rep.farFieldWhy = "geometry-all draws every triangle in the frustum; no far field";
    } else if (mode == RenderMode::RaycastAll) {
      rep.farFieldRan = true;
      rep.farFieldWhy = "raycast-all casts a ray through every pixel";
    } else if (wholeScene) {
      rep.farFieldWhy = fmt::format(
          "the whole scene ({} triangles) fits the polygon budget of {}: drawn as polygons",
          r.liveTriangles_, options.polygonBudget);
    } else if (!options.farFieldAllowed) {
      rep.farFieldWhy = "the scene has no geometry beyond d";
    } else if (!r.grid_.anythingBeyond(camera.eye, d)) {
      rep.farFieldWhy = fmt::format("all geometry lies within d = {:.0f} m of the viewer", d);
    } else {
      rep.farFieldRan = true;
      rep.farFieldWhy = fmt::format("geometry beyond d = {:.0f} m", d);
    }
  }

  // Why horizon tracing and the cache cannot run in this frame at all (empty
  // when they may): another mode, or no far field.
  std::string farStagesOff() const {
    if (!isPipeline(mode)) return fmt::format("{} mode", renderModeName(mode));
    if (!rep.farFieldRan) return "no far field";
    return {};
  }

  // 3b. Horizon tracing, where there is open sky in reach.
  void traceHorizon() {
    Stopwatch clock;
    const PipelineOptions& options = r.options_;
    if (std::string why = farStagesOff(); !why.empty()) {
      rep.horizonWhy = std::move(why);
    } else if (!options.horizonAllowed) {
      rep.horizonWhy = "the scene has no open sky";
    } else if (std::abs(camera.pitchDeg) + 0.5f * camera.vfovDeg >= 89.0f) {
      rep.horizonWhy = "the view reaches the zenith or nadir, where columns are not vertical";
    } else if (r.rays_->occluded(Ray{
                   camera.eye, {0.0f, 1.0f, 0.0f}, 0.0f, std::numeric_limits<float>::infinity()})) {
      rep.horizonWhy = "a ceiling above the viewer: no sky in reach";
    } else {
      const int k = rep.moving ? std::max(1, options.horizonSubsampleMoving) : 1;
      slopes = r.horizon_.trace(camera, d, k, &rep.horizonStats);
      rep.horizonRan = true;
      rep.horizonWhy = k > 1 ? fmt::format("open sky; every {}th column traced while moving", k)
                             : std::string("open sky; every column traced");
    }
    rep.ms.horizon = clock.ms();
  }

  // 4. Classify the uncovered pixels: polygon, background, sky above the
  // horizon, or far-field candidates.
  void classifyPixels() {
    const std::vector<uint8_t>& covered = r.covered_;
    const Camera::PixelRays pixelRays = camera.pixelRays();
    // Colours first, rows in parallel: polygon pixels look theirs up in
    // their triangle's grid, one span per triangle; every other pixel takes
    // the background's (the far field overwrites its own in compose()).
    Stopwatch clock;
    tbb::parallel_for(tbb::blocked_range<int>(0, H, 8), [&](const tbb::blocked_range<int>& rows) {
      // Triangles are set up for the eye as their spans come: only those
      // seen (a fraction of the near field), once for neighbouring rows.
      struct Seen {
        uint32_t t = kNoTriangle;
        EyeTriangle eye;
      };
      std::array<Seen, 64> seen;
      auto setUp = [&](uint32_t t) -> const EyeTriangle& {
        Seen& s = seen[t % seen.size()];
        if (s.t != t) s = Seen{t, EyeTriangle::of(r.geometry_.triangles, t, camera.eye)};
        return s.eye;
      };
      for (int y = rows.begin(); y != rows.end(); ++y) {
        const size_t row = size_t(y) * size_t(W);
        // With OpenGL drawing the near field there are no triangle ids.
        const uint32_t* ids = glNear ? nullptr : r.ids_.ids.data() + row;
        const uint8_t* cov = covered.data() + row;
        for (int x = 0; x < W;) {
          const bool polygon = cov[x] == kCovered;
          const uint32_t t = polygon && ids ? ids[x] : 0;
          int end = x + 1;
          while (end < W && (cov[end] == kCovered) == polygon &&
                 (!polygon || !ids || ids[end] == t))
            ++end;
          const glm::vec3 first = pixelRays.at(float(x) + 0.5f, float(y) + 0.5f);
          uint8_t* o = out.pixels.data() + 3 * (row + size_t(x));
          if (!polygon)
            r.geometry_.shadeBackground(camera.eye, first, pixelRays.perX, end - x, o);
          else if (!glNear)
            r.geometry_.shadeSpan(t, setUp(t), first, pixelRays.perX, end - x, o);
          x = end;
        }
      }
    });
    rep.ms.shade = clock.ms();
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const size_t p = size_t(y) * size_t(W) + size_t(x);
        if (covered[p] == kCovered) {
          ++rep.pixels.polygon;
          continue;
        }
        const glm::vec3 dir = pixelRays.at(float(x) + 0.5f, float(y) + 0.5f);
        if (!rep.farFieldRan) {
          ++rep.pixels.background;
          if (covered[p] == kUncovered) backgroundPixels.push_back(uint32_t(p));
          continue;
        }
        // Only pixels no polygon reaches can be sky: the horizon bounds the far
        // field, and a pixel with a polygon beyond d sees at least that.
        if (rep.horizonRan && covered[p] == kUncovered &&
            HorizonMap::raySlope(dir) > slopes[size_t(x)]) {
          ++rep.pixels.horizon;
          skyPixels.push_back(uint32_t(p));
          continue;
        }
        candidates.push_back(uint32_t(p));
        dirs.push_back(dir);
      }
    if (glNear)
      for (size_t p = 0; p < pixels; ++p)
        if (covered[p] == kCovered) setPixel(p, sky);
  }

  // 5. The image cache decides which candidates to retrace.
  void planCache() {
    Stopwatch clock;
    const PipelineOptions& options = r.options_;
    useCache = isPipeline(mode) && options.cache && rep.farFieldRan;
    if (std::string why = farStagesOff(); !why.empty()) {
      rep.cacheWhy = std::move(why);
    } else if (!options.cache) {
      rep.cacheWhy = "switched off";
    }
    if (!useCache) {
      trace.assign(candidates.size(), 1);
      rep.ms.cache = clock.ms();
      return;
    }
    if (!r.cache_ || r.cachePixelAngle_ != camera.pixelAngle()) {
      r.cachePixelAngle_ = camera.pixelAngle();
      r.cache_ = std::make_unique<PanoramicCache>(r.cachePixelAngle_, options.cacheOptions);
      r.cachedImpostors_.reset();
    }
    syncCacheImpostors();
    texels.resize(candidates.size());
    for (size_t i = 0; i < candidates.size(); ++i) texels[i] = r.cache_->texelOf(dirs[i]);
    const float maxStale = options.maxStalePixels * camera.pixelAngle() * d;
    rep.cachePlan =
        r.cache_->plan(camera.eye, texels, options.pixelBudget, maxStale, trace, turned);
    rep.cacheRan = true;
    rep.cacheWhy =
        rep.cachePlan.degraded
            ? "far-field pixels to fill; the ray budget ran out, older pixels wait for later frames"
            : "far-field pixels to fill; every pixel outside the error bound retraced";
    rep.ms.cache = clock.ms();
  }

  // The impostor set this frame splats in software (null: none): the
  // conditions of splatImpostors() that do not depend on the pixels.
  std::shared_ptr<const ImpostorSet> softwareImpostors() const {
    const auto& set = r.impostors_;
    if (gpu || !isPipeline(mode) || mode == RenderMode::ImpostorOff || !set ||
        !set->cell.contains(camera.eye) || set->impostors.empty())
      return nullptr;
    return set;
  }
  // The cache holds the far field composited with the impostors drawn: when
  // those change, it forgets the texels that showed the old ones and those
  // the new ones may hide.
  void syncCacheImpostors() {
    std::shared_ptr<const ImpostorSet> now = softwareImpostors();
    if (now == r.cachedImpostors_) return;
    std::vector<Box3f> boxes;
    if (now)
      for (const auto& impostor : now->impostors) boxes.push_back(impostor->box);
    rep.impostorTexelsForgotten = r.cache_->invalidate(boxes, {}, true);
    r.cachedImpostors_ = std::move(now);
  }

  // 7. Ray casting (after the impostors: a ray need not look beyond the
  // point a pixel already shows).
  void castFarRays() {
    Stopwatch clock;
    const bool splatted = impostorsOn && !gpu;
    for (size_t i = 0; i < candidates.size(); ++i)
      if (trace[i]) {
        // dirs[i] has a unit component along the view axis, so t is the view
        // depth: starting at zNear clips rays exactly where polygons are clipped.
        float tfar = std::numeric_limits<float>::infinity();
        // A hit at or beyond this depth loses to the pixel's point
        // (impostorCovers): no need to find it.
        const float z = splatted ? r.splatter_.score()[candidates[i]] : ImpostorSplatter::kEmpty;
        if (z < ImpostorSplatter::kEmpty) tfar = std::max(camera.zNear, (z - 0.01f) / 1.001f);
        rays.push_back(Ray{camera.eye, dirs[i], camera.zNear, tfar});
        rayOf.push_back(uint32_t(i));
      }
    castRays(*r.rays_, rays, hits);
    rep.ms.raycast = clock.ms();
  }

  // 6. Impostors of the viewer's cell, splatted; compose() keeps a point
  // where the far field's own hit is not nearer.
  bool impostorsOn = false;
  void splatImpostors() {
    Stopwatch clock;
    const ImpostorSet* set = r.impostors_.get();
    if (!isPipeline(mode)) {
      rep.impostorsWhy = fmt::format("{} mode", renderModeName(mode));
    } else if (mode == RenderMode::ImpostorOff) {
      rep.impostorsWhy = "impostor-off mode";
    } else if (!set) {
      rep.impostorsWhy = "no impostors held for the viewer's cell";
    } else if (!set->cell.contains(camera.eye)) {
      rep.impostorsWhy =
          fmt::format("the impostors held are for cell ({}, {}, {}), not the viewer's",
                      set->index.x, set->index.y, set->index.z);
    } else if (set->impostors.empty()) {
      rep.impostorsWhy = "the viewer's cell has no impostors: " + set->why;
    } else if (candidates.empty() && skyPixels.empty() && backgroundPixels.empty()) {
      rep.impostorsWhy = "no far-field pixels to fill";
    } else if (gpu) {
      // Those whose footprint meets a pixel they may fill (far-field,
      // horizon-sky or background): not those behind the near field's walls.
      ScreenTiles tiles;
      tiles.reset(W, H);
      for (const std::vector<uint32_t>* list : {&candidates, &skyPixels, &backgroundPixels})
        tiles.markList(*list);
      for (const auto& impostor : set->impostors)
        if (tiles.mayCover(camera, impostor->box)) gpu->impostors.push_back(impostor);
      gpu->depthLimit.assign(pixels, 0.0f);
      gpu->splat = r.options_.splat;
      impostorsOn = true;
      rep.impostorsRan = true;
      rep.impostorsDrawn = gpu->impostors.size();
      rep.impostorsWhy = fmt::format("{} impostor{} of the viewer's cell ({}, {}, {}), by OpenGL",
                                     set->impostors.size(), set->impostors.size() == 1 ? "" : "s",
                                     set->index.x, set->index.y, set->index.z);
    } else if (!maskSplat(*set)) {
      rep.impostorsWhy =
          "no pixel to splat: the image cache holds the impostors drawn, or none is in reach";
    } else {
      r.splatter_.begin(camera, &r.splatMask_, r.options_.splat);
      if (r.impostorImage_.width != W || r.impostorImage_.height != H)
        r.impostorImage_ = ImageRgb8(W, H);
      // The splatter skips an impostor (or a block of its points) over no
      // pixel of the mask: behind the near field's walls.
      std::vector<const Impostor*> all;
      for (const auto& impostor : set->impostors) all.push_back(impostor.get());
      std::vector<size_t> landed;
      rep.impostorPoints += r.splatter_.draw(all, r.impostorImage_, &landed);
      rep.impostorsDrawn +=
          size_t(std::count_if(landed.begin(), landed.end(), [](size_t n) { return n > 0; }));
      impostorsOn = true;
      rep.impostorsRan = true;
      rep.impostorsWhy = fmt::format("{} impostor{} of the viewer's cell ({}, {}, {})",
                                     set->impostors.size(), set->impostors.size() == 1 ? "" : "s",
                                     set->index.x, set->index.y, set->index.z);
    }
    rep.ms.impostors = clock.ms();
  }
  // The pixels compose may give an impostor (splatMask_): those traced this
  // frame, sky and background (the cache's texels hold the impostors
  // already), and of those only the ones a block of some impostor's points
  // may reach. False when there are none.
  bool maskSplat(const ImpostorSet& set) {
    ScreenTiles& reach = r.splatReach_;
    reach.reset(W, H);
    for (const auto& impostor : set.impostors) reach.markReach(camera, *impostor);
    r.splatMask_.reset(pixels);
    if (!reach.any()) return false;
    PixelRows rows(W);
    for (size_t i = 0; i < candidates.size(); ++i)
      if (trace[i] && reach.marked(rows.at(candidates[i]))) r.splatMask_.add(candidates[i]);
    for (const std::vector<uint32_t>* list : {&skyPixels, &backgroundPixels}) {
      PixelRows listRows(W);
      for (const uint32_t p : *list)
        if (reach.marked(listRows.at(p))) r.splatMask_.add(p);
    }
    return !r.splatMask_.pixels().empty();
  }
  // Whether candidate i shows the impostor rather than the far field's hit
  // at view depth `farDepth` (infinity: a miss).
  bool impostorWins(size_t i, float farDepth) const {
    return impostorsOn && impostorCovers(candidates[i], farDepth);
  }
  // A point lies on the surface it samples: within a few millimetres of the
  // same surface's ray hit, so the impostor wins ties.
  static float impostorDepthLimit(float farDepth) { return farDepth * 1.001f + 0.01f; }
  bool impostorCovers(size_t p, float farDepth) const {
    if (gpu) {  // the GPU splats; it needs the limit, the far field keeps its pixel
      gpu->depthLimit[p] = impostorDepthLimit(farDepth);
      return false;
    }
    const float z = r.splatter_.score()[p];
    return z < ImpostorSplatter::kEmpty && z <= impostorDepthLimit(farDepth);
  }
  void takeImpostor(size_t i) { takeImpostorPixel(candidates[i]); }
  glm::u8vec3 impostorColour(size_t p) const {
    return r.impostorImage_.at(int(p % size_t(W)), int(p / size_t(W)));
  }
  void takeImpostorPixel(size_t p) {
    setPixel(p, impostorColour(p));
    ++rep.pixels.impostor;
  }

  // 8. Compose: ray colours (stored in the cache), then cached colours,
  // impostors in front of either.
  void compose() {
    Stopwatch clock;
    for (size_t k = 0; k < rays.size(); ++k) {
      const size_t i = rayOf[k];
      const Hit& h = hits[k];
      const glm::u8vec3 c =
          h.valid() ? r.geometry_.colourAt(h.triangle, h.u, h.v, h.t * glm::length(dirs[i]))
                    : r.geometry_.background(camera.eye, dirs[i]);
      // dirs[i] has unit view depth: the hit's t is its view depth.
      const bool impostor =
          impostorWins(i, h.valid() ? h.t : std::numeric_limits<float>::infinity());
      // The cache keeps what the pixel shows: the impostor's point (at its
      // score, a depth at most 2% beyond the point's: invalidate() then
      // forgets a little more), or the far field's hit. A shortened ray
      // that missed lost to its point (impostorCovers), so every ray stores.
      if (useCache && texels[i] >= 0) {
        if (impostor)
          r.cache_->store(texels[i], impostorColour(candidates[i]),
                          r.splatter_.score()[candidates[i]] * glm::length(dirs[i]),
                          PanoramicCache::kImpostorTexelHit);
        else
          r.cache_->store(
              texels[i], c,
              h.valid() ? h.t * glm::length(dirs[i]) : std::numeric_limits<float>::infinity(),
              h.valid() ? h.triangle : PanoramicCache::kNoTexelHit);
      }
      if (impostor) {
        takeImpostor(i);
        continue;
      }
      hits[k].valid() ? ++rep.pixels.rayHit : ++rep.pixels.rayMiss;
      setPixel(candidates[i], c);
    }
    if (useCache)
      for (size_t i = 0; i < candidates.size(); ++i)
        if (!trace[i]) {
          // Software frames splat no cached pixel (the texel holds the
          // composite); OpenGL frames need the depth limit of every one.
          if (impostorWins(i, r.cache_->hitDistance(texels[i]) / glm::length(dirs[i]))) {
            takeImpostor(i);
            continue;
          }
          r.cache_->showsImpostor(texels[i]) ? ++rep.pixels.impostor : ++rep.pixels.cache;
          setPixel(candidates[i], r.cache_->colour(texels[i]));
        }
    // Above the horizon of the geometry held there is none: an impostor's
    // far geometry (which the client does not hold) may rise there.
    if (impostorsOn)
      for (const uint32_t p : skyPixels)
        if (impostorCovers(p, std::numeric_limits<float>::infinity())) {
          --rep.pixels.horizon;
          takeImpostorPixel(p);
        }
    // Nor where the client holds no far field at all.
    if (impostorsOn)
      for (const uint32_t p : backgroundPixels)
        if (impostorCovers(p, std::numeric_limits<float>::infinity())) {
          --rep.pixels.background;
          takeImpostorPixel(p);
        }
    rep.ms.compose = clock.ms();
  }
};

FrameReport FrameRenderer::run(const Camera& camera, ImageRgb8& out, std::vector<uint32_t>* glNear,
                               GpuImpostors* gpu) {
  Stopwatch total;
  if (gpu) {
    gpu->impostors.clear();
    gpu->depthLimit.clear();
  }
  FrameRun f(*this, camera, out, glNear, gpu);
  f.trackMotion();
  f.selectNearField();
  f.drawPolygons();
  f.decideFarField();
  f.traceHorizon();
  f.classifyPixels();
  f.planCache();
  f.splatImpostors();
  f.castFarRays();
  f.compose();
  f.rep.ms.total = total.ms();
  return std::move(f.rep);
}

size_t FrameRenderer::drawDynamic(const Camera& camera, const RenderGeometry& dynamic,
                                  ImageRgb8& out) {
  const size_t n = dynamic.size();
  if (n == 0) return 0;
  VS_CHECK(idsDrawn_ && ids_.width == camera.width && ids_.height == camera.height);
  VS_CHECK(out.width == camera.width && out.height == camera.height);
  dynamicWhich_.resize(n);
  for (size_t t = 0; t < n; ++t) dynamicWhich_[t] = uint32_t(t);
  dynamicRaster_.draw(camera, dynamic.triangles, dynamicWhich_, dynamicIds_, polygonDistance());
  const int W = camera.width, H = camera.height;
  const Camera::PixelRays pixelRays = camera.pixelRays();
  std::vector<EyeTriangle> seen(n);
  for (size_t t = 0; t < n; ++t) seen[t] = EyeTriangle::of(dynamic.triangles, t, camera.eye);
  // Fragments that pass the near field's depth test.
  std::vector<uint32_t> pixels;
  for (size_t p = 0; p < size_t(W) * size_t(H); ++p) {
    const uint32_t id = dynamicIds_.ids[p];
    if (id >= kBeyondDistance) continue;
    const uint32_t near = ids_.ids[p];
    if (near < kBeyondDistance && ids_.inverseDepth[p] >= dynamicIds_.inverseDepth[p]) continue;
    pixels.push_back(uint32_t(p));
  }
  // Raycast-all frames have no near field: the static scene's rays decide.
  std::vector<uint8_t> hidden(pixels.size(), 0);
  if (options_.mode == RenderMode::RaycastAll && !pixels.empty()) {
    std::vector<Ray> rays(pixels.size());
    for (size_t k = 0; k < pixels.size(); ++k) {
      const size_t p = pixels[k];
      const glm::vec3 dir = pixelRays.at(float(p % size_t(W)) + 0.5f, float(p / size_t(W)) + 0.5f);
      // The fragment's view depth is 1 / inverseDepth; dir has unit depth.
      rays[k] = Ray{camera.eye, dir, 0.0f, 1.0f / dynamicIds_.inverseDepth[p]};
    }
    rays_->occludedMany(rays, hidden);
  }
  size_t drawn = 0;
  for (size_t k = 0; k < pixels.size(); ++k) {
    if (hidden[k]) continue;
    const size_t p = pixels[k];
    const int x = int(p % size_t(W)), y = int(p / size_t(W));
    const uint32_t t = dynamicIds_.ids[p];
    out.set(x, y, dynamic.colourAlong(t, seen[t], pixelRays.at(float(x) + 0.5f, float(y) + 0.5f)));
    ++drawn;
  }
  return drawn;
}

}  // namespace vistream
