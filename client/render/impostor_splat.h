// The software renderer of point-based impostors (common/impostor/impostor.h):
// what the OpenGL renderer's point shader does, on the CPU, for headless
// frames and tests.
//
// Each point is projected with the camera (the same rotation-projection as
// every renderer, camera.h) and covers the pixels whose centres lie within
// PointSplat::radius of its projection: a disc inside the 2x2 pixels whose
// centres surround it (an OpenGL point of size 2 whose fragments beyond the
// radius are discarded). A pixel keeps the point of least score, its depth
// (distance along the view axis) raised by PointSplat::sameSurface times
// (d / radius)^2 for its distance d from the pixel's centre: of two points
// of one surface (depths within sameSurface of each other) the one nearer
// the pixel's centre wins, so a crease or a roof line stays where it is
// instead of moving a pixel towards the viewer; of two surfaces further
// apart in depth the nearer wins; of equal scores the first drawn. The
// pixel takes the winner's colour seen from the eye (Impostor::colourSeenFrom:
// its texture at the eye's sampling-plane coordinates, bilinear). Points
// behind the near plane or projecting off the screen are skipped whole, as
// OpenGL clips a point by its centre.
//
// Why a disc of 0.7 pixels and not the thesis's 2x2 square: the bake spaces
// samples at most 1 / (P sqrt 2) pixels apart for every viewer in the cell
// (ScreenSpec::sampleAngle; the perspective factor P is 1.33 on the 60-degree
// screen, 0.53 pixels, and 1.17 on the thesis's 45-degree one, 0.6), so a
// pixel centre on a sampled surface has a point within half a pixel, plus
// what the seams between cameras and layers add; the 2x2 square reaches up to a
// pixel (a diagonal 1.4) beyond a silhouette and widens every building by a
// pixel. Measured along walks through street cells (bench_impostor_image,
// 640x480, 12 frames): radii of 0.6 and 0.65 pixels leave 2 to 4 footprint
// pixels uncovered on bigcity and on the real city model, 0.7 none; against
// the supersampled reference the disc takes the real city model's error on
// the impostors' footprint from 2.76 to about 1.2 levels, below raw
// geometry's 1.25. sameSurface = 0.02 (2% of the depth at the rim) was the
// best of 0, 0.01, 0.02 and 0.04 on both scenes taken together.
//
// draw() runs in parallel inside (projection by chunks of points, the depth
// test by bands of rows), with the result of one pass in the points' order.
//
// Thread safety: one ImpostorSplatter per viewer.
#pragma once

#include <tbb/enumerable_thread_specific.h>

#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "client/render/camera.h"
#include "client/render/image.h"
#include "common/core/ivec_less.h"
#include "common/impostor/impostor.h"

namespace vistream {

// The impostors of one view cell, as received (connected) or baked: valid
// for viewpoints inside `cell`.
struct ImpostorSet {
  // The view cell: grid cells index..indexHi (inclusive; cells merged along
  // a street share one set), and their box.
  glm::ivec3 index{0}, indexHi{0};
  Box3f cell;
  bool holds(const glm::ivec3& gridCell) const { return cellWithin(gridCell, index, indexHi); }
  std::vector<std::shared_ptr<const Impostor>> impostors;
  uint32_t expected = 0;  // impostors the cell has (received: as announced)
  std::string why;        // the bake's reason (why these, or why none)
  size_t bytes = 0;       // as received
};

// The pixels (x0, y0, x1, y1, inclusive) the points inside `box` may cover
// in the camera's frame: the whole screen when the box reaches behind the
// near plane, nothing when it lies wholly out of view.
std::optional<glm::ivec4> impostorFootprint(const Camera& camera, const Box3f& box);

// How a point covers pixels: the software splatter and the OpenGL point
// shader (client/gl/gl_renderer.h) apply the same rule.
struct PointSplat {
  float radius = 0.7f;        // pixels, in (0, 1): a point covers the pixel centres this near
  float sameSurface = 0.02f;  // relative depth: the score's rise at the radius
  // The score the depth test compares: depth * (1 + sameSurface (d / radius)^2).
  float score(float depth, float d2) const {
    return depth * (1.0f + sameSurface / (radius * radius) * d2);
  }
};

// A pixel's column and row from its index y * width + x, the row found by a
// division only when it changes: cheap over a list that runs in rows.
class PixelRows {
 public:
  explicit PixelRows(int width) : width_(uint32_t(width)) {}
  glm::ivec2 at(uint32_t p) {
    if (p - rowStart_ >= width_) {  // another row (unsigned: also before rowStart_)
      y_ = p / width_;
      rowStart_ = y_ * width_;
    }
    return {int(p - rowStart_), int(y_)};
  }

 private:
  uint32_t width_, rowStart_ = 0, y_ = 0;
};

// A set of pixels (index y * width + x, row 0 at the top): a byte a pixel
// and the list of those set, so that filling and clearing it cost as much
// as the pixels set, not the screen.
class PixelMask {
 public:
  // Nothing set, room for `pixels`.
  void reset(size_t pixels) {
    if (bytes_.size() == pixels) {
      for (const uint32_t p : set_) bytes_[p] = 0;
    } else {
      bytes_.assign(pixels, 0);
    }
    set_.clear();
  }
  void add(uint32_t p) {
    if (!bytes_[p]) {
      bytes_[p] = 1;
      set_.push_back(p);
    }
  }
  bool has(size_t p) const { return bytes_[p] != 0; }
  size_t size() const { return bytes_.size(); }
  std::span<const uint32_t> pixels() const { return set_; }

 private:
  std::vector<uint8_t> bytes_;
  std::vector<uint32_t> set_;
};

// Which tiles of kTile x kTile pixels hold a pixel an impostor may fill,
// so that an impostor, or a block of its points, whose footprint meets none
// is skipped whole (the software splatter with its mask, the pipeline for
// the OpenGL splat).
class ScreenTiles {
 public:
  static constexpr int kTile = 16;
  // No tile marked.
  void reset(int width, int height);
  // Marks the tiles holding a pixel of the list (of the camera's pixels; a
  // list in ascending order costs no division a pixel: PixelRows).
  void markList(std::span<const uint32_t> pixels);
  // Marks the tiles holding a pixel of `mask`.
  void markMask(const PixelMask& mask);
  // Marks the tiles where a point of the impostor may land: the footprint
  // (impostorFootprint) of each block of its points, or of its box.
  void markReach(const Camera& camera, const Impostor& impostor);
  bool any() const;
  bool marked(glm::ivec2 pixel) const {
    return tiles_[size_t(pixel.y / kTile) * size_t(tilesX_) + size_t(pixel.x / kTile)] != 0;
  }
  // Whether a point inside `box` may land on a marked tile (impostorFootprint).
  bool mayCover(const Camera& camera, const Box3f& box) const;

 private:
  int width_ = 0, height_ = 0, tilesX_ = 0;
  std::vector<uint8_t> tiles_;
};

class ImpostorSplatter {
 public:
  // Starts a frame of the camera's size: every depth at infinity. With
  // `mask` (of the camera's pixels, kept alive until the frame's last draw),
  // only its pixels are drawn: the others keep their depth at infinity and
  // their colour.
  // Throws InputError on a splat radius outside (0, 1) or a negative or
  // non-finite sameSurface.
  void begin(const Camera& camera, const PixelMask* mask = nullptr, const PointSplat& splat = {});
  // Draws an impostor's points into the frame's depth and `out` (which has
  // the camera's size). Returns the points that landed on the screen (with
  // a mask, those over a pixel it lets through: the others are skipped, a
  // block of points over none of its tiles unprojected).
  size_t draw(const Impostor& impostor, ImageRgb8& out);
  // Draws several impostors in one pass, as draw() one after another would
  // (a pixel keeps the first of equal scores, in the impostors' order), at
  // the cost of one. Returns the points that landed, and in `landedEach`
  // (when given) those of each impostor.
  size_t draw(std::span<const Impostor* const> impostors, ImageRgb8& out,
              std::vector<size_t>* landedEach = nullptr);
  // A draw of fewer points than this (in the impostors that may cover a
  // pixel) runs on the calling thread: a few thousand points take less time
  // than waking the worker threads. Both ways draw the same frame.
  void setSerialBelow(size_t points) { serialBelow_ = points; }
  static constexpr size_t kSerialBelow = 16384;

  // Per pixel, the depth of the point that won it (kEmpty: no point).
  const std::vector<float>& depth() const { return depth_; }
  // Per pixel, the winner's score (PointSplat::score; kEmpty: no point):
  // what a depth limit compares, as the OpenGL point shader's depth test does.
  const std::vector<float>& score() const { return score_; }
  bool covered(int x, int y) const {
    return depth_[size_t(y) * size_t(camera_.width) + size_t(x)] < kEmpty;
  }

  static constexpr float kEmpty = 3.0e38f;

 private:
  static constexpr int kSkipped = std::numeric_limits<int>::min();
  static constexpr uint32_t kNoWinner = ~0u;
  struct Projected {
    int x0 = 0, y0 = kSkipped;   // the 2x2 pixels' top left; y0 kSkipped: not drawn
    float fx = 0.0f, fy = 0.0f;  // the projection from the top left pixel's centre
    float z = 0.0f;
  };
  // Projects a point (y0 kSkipped and false when it is not drawn).
  bool project(const glm::vec3& point, Projected& pr) const;
  // Whether a projected point's 2x2 pixels hold one of the mask's.
  bool overMask(const Projected& pr) const;
  // False when no point inside `bounds` can land on a pixel the mask lets through.
  bool mayCover(const Box3f& bounds) const;

  Camera camera_;
  glm::mat4 rotationProjection_{1.0f};
  glm::vec3 forward_{0.0f, 0.0f, -1.0f};
  const PixelMask* mask_ = nullptr;
  ScreenTiles maskTiles_;  // the tiles the mask lets a point into
  PointSplat splat_;
  size_t serialBelow_ = kSerialBelow;
  std::vector<float> depth_, score_;
  // Scratch of draw(): per point its projection, per pixel the point that
  // won it in this draw, per band of rows the pixels won.
  std::vector<Projected> projected_;
  std::vector<uint32_t> winner_;
  int bands_ = 1, frameWidth_ = 0;
  std::vector<int> bandOfRow_;
  std::vector<glm::ivec2> blockBands_;           // per block of points: its first and last band
  std::vector<uint32_t> blockOwner_;             // per block: its impostor among drawn_
  std::vector<uint32_t> drawn_;                  // the impostors drawn (index into the span)
  std::vector<size_t> firstPoint_, firstBlock_;  // per drawn impostor, then the totals
  std::vector<std::vector<uint32_t>> touched_;   // per band: pixels written this frame
  tbb::enumerable_thread_specific<std::vector<uint32_t>> wonScratch_;
};

}  // namespace vistream
