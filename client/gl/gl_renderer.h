// The OpenGL 3.3 core near field and the frame composition on the GPU.
//
// A frame is drawn in two steps:
//  1. the far-field image (every pixel the opacity buffer left uncovered
//     holds its far-field or sky colour) is drawn as a full-screen texture,
//     without depth;
//  2. the near-field triangles are drawn over it with a depth test, each in
//     its prelit colour (RenderGeometry::colours), flat, unlit; fragments
//     farther than the near-field distance d from the eye are discarded
//     (those pixels belong to the far field); then the dynamic objects
//     (uploadDynamic) the same way.
// Between the two, the impostors of the viewer's cell (GpuImpostors, from
// FrameRenderer::renderFarField) are drawn as points by a vertex shader that
// does what client/render/impostor_splat.h does on the CPU.
// A pixel the near field covers shows the near field; any other pixel shows
// the far-field image or an impostor's point. The opacity buffer is made on the CPU with an inset
// (see SoftwareRasterizer::coverage), so every pixel it calls covered is
// covered by the GPU too and no hole can appear.
//
// Needs a current OpenGL 3.3 core context (GlWindow makes one). Not thread
// safe: use from the thread that owns the context.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "client/farfield/pipeline.h"
#include "client/render/camera.h"
#include "client/render/image.h"
#include "client/render/render_geometry.h"

namespace vistream {

struct HudLine {
  std::string text;
};

// Where the HUD's text goes in a window of `width` x `height` pixels: at
// twice stb_easy_font's size (about 14 px glyphs), each line wrapped at its
// field separators (two spaces, else one) so the box fits the width; at
// single size when the wrapped text would cover more than half the height
// or a single word is wider than the window. Printable ASCII only (others
// become '?'). Pure: no GL context needed.
struct HudLayout {
  float scale = 2.0f;                  // pixels per font unit
  std::vector<std::string> lines;      // after wrapping; continuations start with two spaces
  glm::vec2 boxLo{0.0f}, boxHi{0.0f};  // the dark box, pixels from the top left
};
HudLayout layoutHud(std::span<const HudLine> hud, int width, int height);

class GlRenderer {
 public:
  GlRenderer();  // compiles shaders; throws std::runtime_error with the GL log on failure
  ~GlRenderer();
  GlRenderer(const GlRenderer&) = delete;
  GlRenderer& operator=(const GlRenderer&) = delete;

  // Uploads every triangle of `geometry` (positions and colours, unindexed,
  // 3 vertices a triangle, triangle t at vertices 3t..3t+2). Call again when
  // the geometry changed.
  void upload(const RenderGeometry& geometry);
  // Uploads the dynamic objects (avatars) drawn whole after the near field,
  // with the same depth test and maximum distance; an empty geometry draws none.
  void uploadDynamic(const RenderGeometry& geometry);
  // Draws one frame into the current framebuffer (camera.width x camera.height):
  // the far-field image as background, then `impostors`' points where the
  // far field leaves them room (GpuImpostors::depthLimit; each impostor's
  // points are uploaded the first time it is drawn and kept while it is
  // drawn now and then), then triangles `near` (indices into the uploaded
  // geometry) with a depth test, then the HUD lines (top left, white on a
  // dark box) if any.
  void draw(const Camera& camera, const ImageRgb8& farField, std::span<const uint32_t> near,
            float nearDistance = std::numeric_limits<float>::infinity(),
            std::span<const HudLine> hud = {}, const GpuImpostors* impostors = nullptr);
  // Waits until the GPU has finished every command given (for timing).
  void finish() const;
  // Reads the current framebuffer back (row 0 at the top). For output files
  // and tests only; the pipeline itself never reads back.
  ImageRgb8 readBack(int width, int height) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vistream
