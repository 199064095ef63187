// The software renderer of point-based impostors (common/impostor/impostor.h):
// what the OpenGL renderer's point shader does, on the CPU, for headless
// frames and tests.
//
// Each point is projected with the camera (the same rotation-projection as
// every renderer, camera.h) and covers the 2x2 pixels whose centres surround
// its projection (an OpenGL point of size 2); a pixel keeps the nearest
// point (depth: distance along the view axis; the first drawn on a tie) and
// takes that point's colour seen from the eye (Impostor::colourSeenFrom: its
// texture at the eye's sampling-plane coordinates, bilinear). Points behind
// the near plane or projecting off the screen are skipped whole, as OpenGL
// clips a point by its centre.
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
#include <string>
#include <vector>

#include "client/render/camera.h"
#include "client/render/image.h"
#include "common/impostor/impostor.h"

namespace vistream {

// The impostors of one view cell, as received (connected) or baked: valid
// for viewpoints inside `cell`.
struct ImpostorSet {
  glm::ivec3 index{0};
  Box3f cell;
  std::vector<std::shared_ptr<const Impostor>> impostors;
  uint32_t expected = 0;  // impostors the cell has (received: as announced)
  std::string why;        // the bake's reason (why these, or why none)
  size_t bytes = 0;       // as received
};

// The pixels (x0, y0, x1, y1, inclusive) the points inside `box` may cover
// in the camera's frame: the whole screen when the box reaches behind the
// near plane, nothing when it lies wholly out of view.
std::optional<glm::ivec4> impostorFootprint(const Camera& camera, const Box3f& box);

class ImpostorSplatter {
 public:
  // Starts a frame of the camera's size: every depth at infinity. With
  // `mask` (one byte a pixel, row 0 at the top, kept alive until the frame's
  // last draw), only pixels whose byte is non-zero are drawn: the others keep
  // their depth at infinity and their colour.
  void begin(const Camera& camera, const std::vector<uint8_t>* mask = nullptr);
  // Draws an impostor's points into the frame's depth and `out` (which has
  // the camera's size). Returns the points that landed on the screen.
  size_t draw(const Impostor& impostor, ImageRgb8& out);
  // Per pixel, the nearest point's depth (infinity: no point).
  const std::vector<float>& depth() const { return depth_; }
  bool covered(int x, int y) const {
    return depth_[size_t(y) * size_t(camera_.width) + size_t(x)] < kEmpty;
  }

  static constexpr float kEmpty = 3.0e38f;

 private:
  static constexpr int kSkipped = std::numeric_limits<int>::min();
  static constexpr uint32_t kNoWinner = ~0u;
  struct Projected {
    int x0 = 0, y0 = kSkipped;  // the 2x2 pixels' top left; y0 kSkipped: not drawn
    float z = 0.0f;
  };
  Camera camera_;
  const std::vector<uint8_t>* mask_ = nullptr;
  std::vector<float> depth_;
  // Scratch of draw(): per point its projection, per pixel the point that
  // won it in this draw, per band the pixels won.
  std::vector<Projected> projected_;
  std::vector<uint32_t> winner_;
  tbb::enumerable_thread_specific<std::vector<uint32_t>> wonScratch_;
};

}  // namespace vistream
