// The client's frame pipeline (thesis chapter 4, Figure 4.4): near field as
// polygons, then for every pixel the polygons leave uncovered, in order:
// horizon tracing (sky), the panoramic image cache, and ray casting; then
// point-based impostors (thesis chapter 5) where the viewer's cell has them.
//
// Modes:
//  - Pipeline:    the thesis's pipeline as above;
//  - ImpostorOff: the same without impostors (the comparison: a connected
//                 client in this mode does not ask the server for them);
//  - RaycastAll:  every pixel ray cast (the reference image);
//  - GeometryAll: every triangle in the view frustum drawn, no far field
//                 (full polygon rendering, the baseline of Figure 4.8).
// Each stage runs only where the frame calls for it, and the FrameReport
// says which ran and why (far field off when all geometry lies within d of
// the viewer; horizon tracing off without open sky; the cache off when asked).
//
// render() draws the near field with the software rasterizer (headless);
// renderFarField() leaves the near field to the caller (OpenGL) and fills
// only the pixels its opacity buffer (with a 1/8-pixel inset, see
// SoftwareRasterizer::coverage) leaves uncovered.
//
// Impostors (setImpostors): the impostors of the view cell holding the
// viewer, drawn by the software splatter (client/render/impostor_splat.h)
// over the far-field pixels ray cast this frame. Such a pixel takes the
// impostor's colour when an impostor point covers it and the ray's first
// hit is not nearer: geometry the client holds beyond d that no impostor
// replaces (a lighter group, a nearer band) still hides the impostor behind
// it. The far field's rays therefore still run (stopping at the point the
// pixel already shows); what impostors add is the far geometry the client
// does not hold (replaced faces are not streamed), prefiltered.
//
// The image cache holds the far field composited with the impostors: a
// texel where the impostor won keeps its colour and the point's distance
// (PanoramicCache::kImpostorTexelHit), so a pixel the cache reuses needs
// neither a ray nor the splat, whatever it shows. The splat covers only the
// pixels traced this frame and the sky and background pixels (never
// cached). When the impostors drawn change (another cell's set arrives, or
// a frame draws none), the cache forgets the texels that showed the old
// ones and those the new ones' boxes may hide (PanoramicCache::invalidate),
// as it does for streamed geometry. OpenGL frames (renderFarField with
// GpuImpostors) splat on the GPU over an impostor-free cache.
//
// Near field and far field meet at distance d along each pixel's ray, not at
// a grid cell: polygons are drawn only up to d (fragments beyond are
// dropped), and a pixel whose nearest polygon lies beyond d is left to the
// far field, whose rays hit whatever is first. A near-field triangle that
// reaches far beyond d (a long street's ground) can therefore never hide a
// far-field object standing on it.
//
// Thread safety: one FrameRenderer per viewer; its work runs on TBB.
#pragma once

#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "client/farfield/field_grid.h"
#include "client/farfield/horizon.h"
#include "client/farfield/image_cache.h"
#include "client/render/camera.h"
#include "client/render/image.h"
#include "client/render/impostor_splat.h"
#include "client/render/render_geometry.h"
#include "client/render/soft_raster.h"
#include "client/render/streamed_geometry.h"
#include "common/core/stats_fields.h"
#include "common/raycast/embree_ray_query.h"

namespace vistream {

enum class RenderMode { Pipeline, RaycastAll, GeometryAll, ImpostorOff };
const char* renderModeName(RenderMode m);
// The pipeline's stages run (Pipeline or ImpostorOff).
inline bool isPipeline(RenderMode m) {
  return m == RenderMode::Pipeline || m == RenderMode::ImpostorOff;
}

struct PipelineOptions {
  RenderMode mode = RenderMode::Pipeline;
  float nearDistance = 150.0f;  // d, metres
  // Rays a frame for cache refreshes (the must-trace pixels come on top).
  size_t pixelBudget = 2'000;
  // A scene with at most this many triangles is drawn whole as polygons,
  // with no far field (0: always split at d).
  size_t polygonBudget = 500'000;
  // Panoramic image cache on/off.
  bool cache = true;
  // A cached texel expires when the viewer moved so far that far-field
  // geometry at distance d may have shifted by this many pixels.
  float maxStalePixels = 2.0f;
  float horizonCellSize = 8.0f;    // metres, the height field's resolution
  int horizonSubsampleMoving = 4;  // trace every k-th column while the viewer moves
  bool horizonAllowed = true;      // the scene has open sky (SceneEffects::horizonTracing)
  // The scene has geometry beyond d (SceneEffects::farFieldRayCasting).
  bool farFieldAllowed = true;
  float gridCellSize = 0.0f;  // near-field grid cell, metres (0: automatic)
  PanoramicCacheOptions cacheOptions;
  PointSplat splat;  // how an impostor's point covers pixels, in software and OpenGL
};

// Table 4.1 of the thesis: where each pixel's colour came from.
struct PixelCounts {
  size_t polygon = 0;     // covered by near-field polygons
  size_t horizon = 0;     // culled by horizon tracing (sky)
  size_t cache = 0;       // taken from the image cache
  size_t rayHit = 0;      // ray cast and hit
  size_t rayMiss = 0;     // ray cast and missed (sky)
  size_t background = 0;  // no far field to look at (far field off): sky colour
  size_t impostor = 0;    // drawn from an impostor (nearer than the far field's hit)

  PixelCounts& operator+=(const PixelCounts& o) {
    polygon += o.polygon;
    horizon += o.horizon;
    cache += o.cache;
    rayHit += o.rayHit;
    rayMiss += o.rayMiss;
    background += o.background;
    impostor += o.impostor;
    return *this;
  }
  // Every field above, once: FrameReport::toJson, walkthroughJson and
  // walkthroughTable are generated from this list.
  template <class F>
  void forEachField(F&& f) const {
    f(StatField{"polygon", "covered by polygons", ""}, polygon);
    f(StatField{"horizon", "culled by horizon", ""}, horizon);
    f(StatField{"cache", "taken from the cache", ""}, cache);
    f(StatField{"ray_hit", "ray cast and hit", ""}, rayHit);
    f(StatField{"ray_miss", "ray cast and missed", ""}, rayMiss);
    f(StatField{"background", "background (no far field)", ""}, background);
    f(StatField{"impostor", "drawn from impostors", ""}, impostor);
  }
};
static_assert(sizeof(PixelCounts) == 7 * sizeof(size_t),
              "PixelCounts changed: update PixelCounts::forEachField");

struct StageTimes {
  // shade: the colours of polygon pixels (software near field) and of the
  // background, looked up (RenderGeometry::shadeSpan, shadeBackground).
  double nearSelect = 0, nearDraw = 0, shade = 0, opacity = 0, horizon = 0, cache = 0, raycast = 0,
         compose = 0, impostors = 0, total = 0;

  StageTimes& operator+=(const StageTimes& o) {
    nearSelect += o.nearSelect;
    nearDraw += o.nearDraw;
    shade += o.shade;
    opacity += o.opacity;
    horizon += o.horizon;
    cache += o.cache;
    raycast += o.raycast;
    compose += o.compose;
    impostors += o.impostors;
    total += o.total;
    return *this;
  }
  // Every field above, once (see PixelCounts::forEachField).
  template <class F>
  void forEachField(F&& f) const {
    f(StatField{"near_select", "near-field selection", "ms"}, nearSelect);
    f(StatField{"near_draw", "near-field drawing", "ms"}, nearDraw);
    f(StatField{"shade", "colour lookups", "ms"}, shade);
    f(StatField{"opacity", "opacity buffer", "ms"}, opacity);
    f(StatField{"horizon", "horizon tracing", "ms"}, horizon);
    f(StatField{"cache", "cache planning", "ms"}, cache);
    f(StatField{"raycast", "ray casting", "ms"}, raycast);
    f(StatField{"compose", "composition", "ms"}, compose);
    f(StatField{"impostors", "impostor splatting", "ms"}, impostors);
    f(StatField{"total", "frame", "ms"}, total);
  }
};
static_assert(sizeof(StageTimes) == 10 * sizeof(double),
              "StageTimes changed: update StageTimes::forEachField");

struct FrameReport {
  PixelCounts pixels;
  StageTimes ms;
  size_t nearTriangles = 0;
  bool moving = false;
  bool farFieldRan = false, horizonRan = false, cacheRan = false, impostorsRan = false;
  std::string farFieldWhy, horizonWhy, cacheWhy, impostorsWhy;
  size_t impostorsDrawn = 0, impostorPoints = 0;  // impostors splatted, their points on screen
  // Cache texels forgotten this frame because the impostors drawn changed
  // (another view cell's set, or none).
  size_t impostorTexelsForgotten = 0;
  CachePlanStats cachePlan;
  HorizonStats horizonStats;
  nlohmann::json toJson() const;
};

// The impostors an OpenGL frame splats itself (renderFarField with it; the
// point shader of client/gl/gl_renderer.h): those of the viewer's cell, and
// per pixel (row 0 at the top) the greatest view depth at which a point
// still shows there, the rule the software compose applies: 0 where the
// near field covers the pixel, the far field's own hit (with the splat's tie
// margin) where it has one, infinity on sky and background pixels.
struct GpuImpostors {
  std::vector<std::shared_ptr<const Impostor>> impostors;  // empty: none this frame
  std::vector<float> depthLimit;
  PointSplat splat;  // PipelineOptions::splat
};

class FrameRenderer {
 public:
  // `geometry` must outlive the renderer.
  FrameRenderer(const RenderGeometry& geometry, const PipelineOptions& options);
  ~FrameRenderer();

  const PipelineOptions& options() const { return options_; }
  // The headless frame: software near field plus the far field.
  FrameReport render(const Camera& camera, ImageRgb8& out);
  // For an OpenGL near field: the triangles to draw (`near`) and the
  // far-field image (valid wherever the opacity buffer is uncovered).
  // With `gpu`, impostors are left to the OpenGL renderer: the far-field
  // image holds none and `gpu` says what to splat where (pixels.impostor
  // stays 0: the GPU decides the pixels).
  FrameReport renderFarField(const Camera& camera, ImageRgb8& farImage, std::vector<uint32_t>& near,
                             GpuImpostors* gpu = nullptr);
  // Dynamic objects (avatars, client/avatar/avatar_view.h) over the frame
  // render() just drew into `out`, with a depth test against it: against the
  // near field's depth where polygons cover a pixel; elsewhere in
  // raycast-all mode by a shadow ray from the eye to the fragment; the far
  // field lies beyond d, where dynamic fragments are dropped. Colours by
  // barycentrics and haze as for static triangles. Returns the pixels drawn.
  // Not for renderFarField frames: OpenGL draws the dynamic objects there.
  size_t drawDynamic(const Camera& camera, const RenderGeometry& dynamic, ImageRgb8& out);
  // How far from the eye polygons are drawn: d in pipeline mode, unlimited
  // in geometry-all. An OpenGL near field discards fragments beyond it.
  float polygonDistance() const;
  // Forgets the cache and the motion history.
  void reset();
  // The impostors frames may draw from now on (null: none held). Frames whose
  // viewer is outside set->cell draw none and say so.
  void setImpostors(std::shared_ptr<const ImpostorSet> set) { impostors_ = std::move(set); }

  // Takes up a change of the geometry (a StreamedGeometry's slots, changed
  // in place; `geometry` is the object given to the constructor): the new
  // triangles go into the near-field grid, the horizon map and the ray query
  // as one batch, the removed ones leave the grid and the ray query (the
  // horizon map keeps them: too high a horizon stays conservative), and the
  // image cache forgets only the texels the change may alter
  // (PanoramicCache::invalidate). Between changes the renderer draws what a
  // renderer built from scratch over the live triangles draws (with the same
  // gridCellSize, pixel for pixel without the cache). False if the grid
  // would outgrow its cell limit: the renderer is then unusable, build a new one.
  bool update(const GeometryChange& change);
  // Whether the far field may run at all (PipelineOptions::farFieldAllowed),
  // for geometry that has grown.
  void allowFarField(bool allowed) { options_.farFieldAllowed = allowed; }
  // The ray query over the live triangles (for decisions about the scene that
  // need rays, such as the ground plane: built once, here).
  const RayQuery& rays() const { return *rays_; }
  // What the last update() did.
  struct UpdateStats {
    size_t added = 0, removed = 0;
    size_t texelsForgotten = 0;
    bool horizonRebuilt = false;
    double gridMs = 0, raysMs = 0, horizonMs = 0, cacheMs = 0;  // time in each part
  };
  const UpdateStats& lastUpdate() const { return lastUpdate_; }
  // Batches in the ray query (one per update that added triangles): rays
  // slow down as they pile up, so an owner builds a new renderer past a few hundred.
  size_t rayBatches() const { return rays_->batchCount(); }

 private:
  friend struct FrameRun;  // one frame's steps (pipeline.cpp)
  FrameReport run(const Camera& camera, ImageRgb8& out, std::vector<uint32_t>* glNear,
                  GpuImpostors* gpu = nullptr);

  const RenderGeometry& geometry_;
  PipelineOptions options_;
  FieldGrid grid_;
  HorizonMap horizon_;
  std::unique_ptr<BatchedRayQuery> rays_;
  std::unique_ptr<PanoramicCache> cache_;
  SoftwareRasterizer raster_;
  IdBuffer ids_;
  bool idsDrawn_ = false;  // ids_ holds the last frame's near field (not an OpenGL frame)
  std::shared_ptr<const ImpostorSet> impostors_;
  // The impostors the cache's texels were composited with (null: none).
  std::shared_ptr<const ImpostorSet> cachedImpostors_;
  ImpostorSplatter splatter_;
  PixelMask splatMask_;     // the pixels an impostor may fill this frame
  ScreenTiles splatReach_;  // the tiles a point of the viewer's impostors may reach
  ImageRgb8 impostorImage_;
  SoftwareRasterizer dynamicRaster_;
  IdBuffer dynamicIds_;
  std::vector<uint32_t> dynamicWhich_;
  std::vector<uint8_t> covered_;
  std::vector<uint32_t> near_, stamp_;
  uint32_t stampValue_ = 0;
  bool wholeScene_ = false;   // within the polygon budget: no near/far split
  size_t liveTriangles_ = 0;  // geometry_.size() less the removed slots
  UpdateStats lastUpdate_;
  bool havePrevious_ = false;
  glm::vec3 previousEye_{0.0f};
  float previousYaw_ = 0.0f, previousPitch_ = 0.0f;
  float cachePixelAngle_ = 0.0f;
};

}  // namespace vistream
