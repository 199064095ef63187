#include "client/farfield/pipeline.h"

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

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
  switch (m) {
    case RenderMode::Pipeline:
      return "pipeline";
    case RenderMode::RaycastAll:
      return "raycast-all";
    case RenderMode::GeometryAll:
      return "geometry-all";
  }
  return "?";
}

nlohmann::json FrameReport::toJson() const {
  return {
      {"pixels",
       {{"polygon", pixels.polygon},
        {"horizon", pixels.horizon},
        {"cache", pixels.cache},
        {"ray_hit", pixels.rayHit},
        {"ray_miss", pixels.rayMiss},
        {"background", pixels.background}}},
      {"ms",
       {{"near_select", ms.nearSelect},
        {"near_draw", ms.nearDraw},
        {"opacity", ms.opacity},
        {"horizon", ms.horizon},
        {"cache", ms.cache},
        {"raycast", ms.raycast},
        {"compose", ms.compose},
        {"total", ms.total}}},
      {"near_triangles", nearTriangles},
      {"moving", moving},
      {"stages",
       {{"far_field", {{"ran", farFieldRan}, {"why", farFieldWhy}}},
        {"horizon_tracing", {{"ran", horizonRan}, {"why", horizonWhy}}},
        {"image_cache", {{"ran", cacheRan}, {"why", cacheWhy}}}}},
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
  rays_ = makeEmbreeRayQuery(geometry.triangles);
  // A scene small enough for the polygon budget is drawn whole: the far
  // field would cost more than it saves.
  wholeScene_ = options.polygonBudget > 0 && geometry.size() <= options.polygonBudget;
}

FrameRenderer::~FrameRenderer() = default;

void FrameRenderer::reset() {
  cache_.reset();
  havePrevious_ = false;
}

float FrameRenderer::polygonDistance() const {
  return options_.mode == RenderMode::Pipeline && !wholeScene_
             ? options_.nearDistance
             : std::numeric_limits<float>::infinity();
}

FrameReport FrameRenderer::render(const Camera& camera, ImageRgb8& out) {
  return run(camera, out, nullptr);
}

FrameReport FrameRenderer::renderFarField(const Camera& camera, ImageRgb8& farImage,
                                          std::vector<uint32_t>& near) {
  return run(camera, farImage, &near);
}

FrameReport FrameRenderer::run(const Camera& camera, ImageRgb8& out,
                               std::vector<uint32_t>* glNear) {
  Stopwatch total;
  FrameReport rep;
  const int W = camera.width, H = camera.height;
  const size_t pixels = size_t(W) * size_t(H);
  const RenderMode mode = options_.mode;
  const float d = options_.nearDistance;
  const bool turned =
      !havePrevious_ || camera.yawDeg != previousYaw_ || camera.pitchDeg != previousPitch_;
  rep.moving = havePrevious_ && (glm::length(camera.eye - previousEye_) > 1e-3f || turned);
  havePrevious_ = true;
  previousEye_ = camera.eye;
  previousYaw_ = camera.yawDeg;
  previousPitch_ = camera.pitchDeg;
  if (out.width != W || out.height != H) out = ImageRgb8(W, H);

  // 1. Near field: the triangles to draw as polygons.
  const bool wholeScene = mode == RenderMode::Pipeline && wholeScene_;
  Stopwatch clock;
  if (mode == RenderMode::RaycastAll)
    near_.clear();
  else
    grid_.nearField(
        camera,
        mode == RenderMode::GeometryAll || wholeScene ? std::numeric_limits<float>::infinity() : d,
        near_, stamp_, stampValue_);
  rep.nearTriangles = near_.size();
  rep.ms.nearSelect = clock.ms();

  // 2. Polygons and the opacity buffer.
  clock = Stopwatch();
  if (glNear) {
    *glNear = near_;
    raster_.coverage(camera, geometry_.triangles, near_, kGlInsetPx, covered_, polygonDistance());
    rep.ms.opacity = clock.ms();
  } else {
    raster_.draw(camera, geometry_.triangles, near_, ids_, polygonDistance());
    rep.ms.nearDraw = clock.ms();
    clock = Stopwatch();
    covered_.resize(pixels);
    for (size_t p = 0; p < pixels; ++p)
      covered_[p] = ids_.ids[p] == kNoTriangle       ? kUncovered
                    : ids_.ids[p] == kBeyondDistance ? kBeyond
                                                     : kCovered;
    rep.ms.opacity = clock.ms();
  }

  // 3. What the far field calls for in this frame.
  if (mode == RenderMode::GeometryAll) {
    rep.farFieldWhy = "geometry-all draws every triangle in the frustum; no far field";
  } else if (mode == RenderMode::RaycastAll) {
    rep.farFieldRan = true;
    rep.farFieldWhy = "raycast-all casts a ray through every pixel";
  } else if (wholeScene) {
    rep.farFieldWhy = fmt::format(
        "the whole scene ({} triangles) fits the polygon budget of {}: drawn as polygons",
        geometry_.size(), options_.polygonBudget);
  } else if (!options_.farFieldAllowed) {
    rep.farFieldWhy = "the scene has no geometry beyond d";
  } else if (!grid_.anythingBeyond(camera.eye, d)) {
    rep.farFieldWhy = fmt::format("all geometry lies within d = {:.0f} m of the viewer", d);
  } else {
    rep.farFieldRan = true;
    rep.farFieldWhy = fmt::format("geometry beyond d = {:.0f} m", d);
  }

  clock = Stopwatch();
  std::vector<float> slopes;
  if (mode != RenderMode::Pipeline) {
    rep.horizonWhy = fmt::format("{} mode", renderModeName(mode));
  } else if (!rep.farFieldRan) {
    rep.horizonWhy = "no far field";
  } else if (!options_.horizonAllowed) {
    rep.horizonWhy = "the scene has no open sky";
  } else if (std::abs(camera.pitchDeg) + 0.5f * camera.vfovDeg >= 89.0f) {
    rep.horizonWhy = "the view reaches the zenith or nadir, where columns are not vertical";
  } else if (rays_->occluded(Ray{
                 camera.eye, {0.0f, 1.0f, 0.0f}, 0.0f, std::numeric_limits<float>::infinity()})) {
    rep.horizonWhy = "a ceiling above the viewer: no sky in reach";
  } else {
    const int k = rep.moving ? std::max(1, options_.horizonSubsampleMoving) : 1;
    slopes = horizon_.trace(camera, d, k, &rep.horizonStats);
    rep.horizonRan = true;
    rep.horizonWhy = k > 1 ? fmt::format("open sky; every {}th column traced while moving", k)
                           : std::string("open sky; every column traced");
  }
  rep.ms.horizon = clock.ms();

  // 4. Classify the uncovered pixels.
  std::vector<uint32_t> candidates;
  std::vector<glm::vec3> dirs;
  const glm::u8vec3 sky = geometry_.sky;
  const Camera::PixelRays pixelRays = camera.pixelRays();
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const size_t p = size_t(y) * size_t(W) + size_t(x);
      if (covered_[p] == kCovered) {
        ++rep.pixels.polygon;
        if (!glNear) out.set(x, y, geometry_.colours[ids_.ids[p]]);
        continue;
      }
      if (!rep.farFieldRan) {
        ++rep.pixels.background;
        out.set(x, y, sky);
        continue;
      }
      const glm::vec3 dir = pixelRays.at(float(x) + 0.5f, float(y) + 0.5f);
      // Only pixels no polygon reaches can be sky: the horizon bounds the far
      // field, and a pixel with a polygon beyond d sees at least that.
      if (rep.horizonRan && covered_[p] == kUncovered &&
          HorizonMap::raySlope(dir) > slopes[size_t(x)]) {
        ++rep.pixels.horizon;
        out.set(x, y, sky);
        continue;
      }
      candidates.push_back(uint32_t(p));
      dirs.push_back(dir);
    }
  if (glNear)
    for (size_t p = 0; p < pixels; ++p)
      if (covered_[p] == kCovered) out.set(int(p % size_t(W)), int(p / size_t(W)), sky);

  // 5. The image cache decides which candidates to retrace.
  clock = Stopwatch();
  std::vector<uint8_t> trace;
  std::vector<int64_t> texels;
  const bool useCache = mode == RenderMode::Pipeline && options_.cache && rep.farFieldRan;
  if (mode != RenderMode::Pipeline) {
    rep.cacheWhy = fmt::format("{} mode", renderModeName(mode));
  } else if (!rep.farFieldRan) {
    rep.cacheWhy = "no far field";
  } else if (!options_.cache) {
    rep.cacheWhy = "switched off";
  }
  if (useCache) {
    if (!cache_ || cachePixelAngle_ != camera.pixelAngle()) {
      cachePixelAngle_ = camera.pixelAngle();
      cache_ = std::make_unique<PanoramicCache>(cachePixelAngle_, options_.cacheOptions);
    }
    texels.resize(candidates.size());
    for (size_t i = 0; i < candidates.size(); ++i) texels[i] = cache_->texelOf(dirs[i]);
    const float maxStale = options_.maxStalePixels * camera.pixelAngle() * d;
    rep.cachePlan = cache_->plan(camera.eye, texels, options_.pixelBudget, maxStale, trace, turned);
    rep.cacheRan = true;
    rep.cacheWhy =
        rep.cachePlan.degraded
            ? "far-field pixels to fill; the ray budget ran out, older pixels wait for later frames"
            : "far-field pixels to fill; every pixel outside the error bound retraced";
  } else {
    trace.assign(candidates.size(), 1);
  }
  rep.ms.cache = clock.ms();

  // 6. Ray casting.
  clock = Stopwatch();
  std::vector<Ray> rays;
  std::vector<uint32_t> rayOf;
  for (size_t i = 0; i < candidates.size(); ++i)
    if (trace[i]) {
      // dirs[i] has a unit component along the view axis, so t is the view
      // depth: starting at zNear clips rays exactly where polygons are clipped.
      rays.push_back(
          Ray{camera.eye, dirs[i], camera.zNear, std::numeric_limits<float>::infinity()});
      rayOf.push_back(uint32_t(i));
    }
  std::vector<Hit> hits;
  castRays(*rays_, rays, hits);
  rep.ms.raycast = clock.ms();

  // 7. Compose.
  clock = Stopwatch();
  for (size_t r = 0; r < rays.size(); ++r) {
    const size_t i = rayOf[r];
    const glm::u8vec3 c = hits[r].valid() ? geometry_.colours[hits[r].triangle] : sky;
    hits[r].valid() ? ++rep.pixels.rayHit : ++rep.pixels.rayMiss;
    const uint32_t p = candidates[i];
    out.set(int(p % uint32_t(W)), int(p / uint32_t(W)), c);
    if (useCache && texels[i] >= 0) cache_->store(texels[i], c);
  }
  if (useCache)
    for (size_t i = 0; i < candidates.size(); ++i)
      if (!trace[i]) {
        ++rep.pixels.cache;
        const uint32_t p = candidates[i];
        out.set(int(p % uint32_t(W)), int(p / uint32_t(W)), cache_->colour(texels[i]));
      }
  rep.ms.compose = clock.ms();
  rep.ms.total = total.ms();
  return rep;
}

}  // namespace vistream
