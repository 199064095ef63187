#include "client/render/impostor_splat.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <functional>

#include "common/core/check.h"
#include "common/light/lighting.h"

namespace vistream {

void ImpostorSplatter::begin(const Camera& camera) {
  camera_ = camera;
  depth_.assign(size_t(camera.width) * size_t(camera.height), kEmpty);
  winner_.assign(depth_.size(), kNoWinner);
}

size_t ImpostorSplatter::draw(const Impostor& impostor, ImageRgb8& out) {
  VS_CHECK(out.width == camera_.width && out.height == camera_.height);
  const glm::mat4 rp = camera_.rotationProjection();
  const glm::vec3 forward = camera_.forward();
  const float w = float(camera_.width), h = float(camera_.height);
  // A box wholly outside the view (beyond a side, or behind the near
  // plane) has no point to draw.
  {
    const float mx = 1.0f, my = 1.0f;
    int left = 0, right = 0, below = 0, above = 0, behind = 0;
    for (int k = 0; k < 8; ++k) {
      const glm::vec3 corner{k & 1 ? impostor.box.hi.x : impostor.box.lo.x,
                             k & 2 ? impostor.box.hi.y : impostor.box.lo.y,
                             k & 4 ? impostor.box.hi.z : impostor.box.lo.z};
      const glm::vec3 rel = corner - camera_.eye;
      if (!(glm::dot(rel, forward) > camera_.zNear)) {
        ++behind;
        continue;
      }
      const glm::vec4 clip = rp * glm::vec4(rel, 1.0f);
      left += clip.x < -mx * clip.w;
      right += clip.x > mx * clip.w;
      below += clip.y < -my * clip.w;
      above += clip.y > my * clip.w;
    }
    if (behind == 8 || left == 8 || right == 8 || below == 8 || above == 8) return 0;
  }
  // 1. Every point projected (in parallel): its 2x2 pixels' corner and depth.
  const size_t n = impostor.size();
  projected_.resize(n);
  const int width = camera_.width, height = camera_.height;
  const size_t landed = tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, n, 4096), size_t(0),
      [&](const tbb::blocked_range<size_t>& range, size_t count) {
        for (size_t k = range.begin(); k < range.end(); ++k) {
          Projected& pr = projected_[k];
          pr.y0 = kSkipped;
          const glm::vec3 rel = impostor.points[k] - camera_.eye;
          const float z = glm::dot(rel, forward);
          if (!(z > camera_.zNear)) continue;
          const glm::vec4 clip = rp * glm::vec4(rel, 1.0f);
          // A point whose projection is off the screen is clipped whole, as
          // OpenGL clips a point by its centre.
          if (!(std::abs(clip.x) <= clip.w && std::abs(clip.y) <= clip.w)) continue;
          // Window coordinates, row 0 at the top (camera.h); the 2x2 pixels
          // whose centres (x + 0.5, y + 0.5) surround (px, py).
          const float px = (clip.x / clip.w * 0.5f + 0.5f) * w;
          const float py = (0.5f - clip.y / clip.w * 0.5f) * h;
          pr.x0 = int(std::floor(px - 0.5f));
          pr.y0 = int(std::floor(py - 0.5f));
          pr.z = z;
          ++count;
        }
        return count;
      },
      std::plus<size_t>());
  // 2. Depth test in bands of rows, each band in parallel, every band's
  // points in the impostor's order, so a pixel keeps the nearest point and
  // of equals the first, as one pass would. 3. Each pixel a point won takes
  // that point's colour seen from the eye.
  winner_.resize(depth_.size());
  const int bands =
      std::max(1, std::min(height / 8, 4 * int(tbb::this_task_arena::max_concurrency())));
  tbb::parallel_for(0, bands, [&](int band) {
    const int rowLo = band * height / bands, rowHi = (band + 1) * height / bands;
    std::vector<uint32_t>& won = wonScratch_.local();
    won.clear();
    for (size_t k = 0; k < n; ++k) {
      const Projected& pt = projected_[k];
      if (pt.y0 == kSkipped || pt.y0 + 1 < rowLo || pt.y0 >= rowHi) continue;
      for (int y = std::max(pt.y0, rowLo); y <= std::min(pt.y0 + 1, rowHi - 1); ++y)
        for (int x = std::max(pt.x0, 0); x <= std::min(pt.x0 + 1, width - 1); ++x) {
          const size_t p = size_t(y) * size_t(width) + size_t(x);
          if (!(pt.z < depth_[p])) continue;
          if (winner_[p] == kNoWinner) won.push_back(uint32_t(p));
          depth_[p] = pt.z;
          winner_[p] = uint32_t(k);
        }
    }
    for (uint32_t p : won) {
      out.set(int(p % uint32_t(width)), int(p / uint32_t(width)),
              toBytes(impostor.colourSeenFrom(winner_[p], camera_.eye)));
      winner_[p] = kNoWinner;
    }
  });
  return landed;
}

}  // namespace vistream
