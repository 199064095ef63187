#include "client/render/impostor_splat.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <mutex>

#include "common/core/check.h"
#include "common/core/error.h"
#include "common/light/lighting.h"

namespace vistream {

void ImpostorSplatter::begin(const Camera& camera, const PixelMask* mask, const PointSplat& splat) {
  if (!(splat.radius > 0.0f && splat.radius < 1.0f))
    throwInputError("impostor splat radius must lie between 0 and 1 pixel, got {}", splat.radius);
  if (!(splat.sameSurface >= 0.0f) || !std::isfinite(splat.sameSurface))
    throwInputError("impostor splat same-surface depth must be a non-negative number, got {}",
                    splat.sameSurface);
  camera_ = camera;
  splat_ = splat;
  VS_CHECK(!mask || mask->size() == size_t(camera.width) * size_t(camera.height));
  mask_ = mask;
  const size_t pixels = size_t(camera.width) * size_t(camera.height);
  // Every pixel at infinity: those the last frame wrote are reset, unless
  // the size changed (winner_ is reset by each draw itself).
  if (depth_.size() == pixels && frameWidth_ == camera.width) {
    for (std::vector<uint32_t>& band : touched_) {
      for (uint32_t p : band) depth_[p] = score_[p] = kEmpty;
      band.clear();
    }
  } else {
    depth_.assign(pixels, kEmpty);
    score_.assign(pixels, kEmpty);
    winner_.assign(pixels, kNoWinner);
    touched_.clear();
  }
  frameWidth_ = camera.width;
  rotationProjection_ = camera.rotationProjection();
  forward_ = camera.forward();
  maskTiles_.reset(camera.width, camera.height);
  if (mask) maskTiles_.markMask(*mask);
  // The bands of rows the depth test runs in, one task each.
  bands_ =
      std::max(1, std::min(camera.height / 8, 4 * int(tbb::this_task_arena::max_concurrency())));
  bandOfRow_.resize(size_t(camera.height));
  for (int b = 0; b < bands_; ++b)
    for (int y = b * camera.height / bands_; y < (b + 1) * camera.height / bands_; ++y)
      bandOfRow_[size_t(y)] = b;
  touched_.resize(size_t(bands_));
}

std::optional<glm::ivec4> impostorFootprint(const Camera& camera, const Box3f& box) {
  const glm::mat4 rp = camera.rotationProjection();
  const glm::vec3 forward = camera.forward();
  int left = 0, right = 0, below = 0, above = 0, behind = 0;
  glm::vec2 lo(std::numeric_limits<float>::infinity()), hi(-lo);
  for (int k = 0; k < 8; ++k) {
    const glm::vec3 corner = box.corner(k);
    const glm::vec3 rel = corner - camera.eye;
    if (!(glm::dot(rel, forward) > camera.zNear)) {
      ++behind;
      continue;
    }
    const glm::vec4 clip = rp * glm::vec4(rel, 1.0f);
    left += clip.x < -clip.w;
    right += clip.x > clip.w;
    below += clip.y < -clip.w;
    above += clip.y > clip.w;
    const glm::vec2 px((clip.x / clip.w * 0.5f + 0.5f) * float(camera.width),
                       (0.5f - clip.y / clip.w * 0.5f) * float(camera.height));
    lo = glm::min(lo, px);
    hi = glm::max(hi, px);
  }
  // Wholly beyond one side of the view, or behind the near plane: the
  // points inside are too (the half-spaces are convex).
  if (behind == 8 || left == 8 || right == 8 || below == 8 || above == 8) return std::nullopt;
  if (behind > 0) return glm::ivec4(0, 0, camera.width - 1, camera.height - 1);
  // The corners' projections bound the points'; a point covers the pixels
  // whose centres lie within one pixel of it.
  return glm::ivec4(std::max(0, int(std::floor(lo.x - 1.5f))),
                    std::max(0, int(std::floor(lo.y - 1.5f))),
                    std::min(camera.width - 1, int(std::floor(hi.x + 0.5f))),
                    std::min(camera.height - 1, int(std::floor(hi.y + 0.5f))));
}

bool ImpostorSplatter::project(const glm::vec3& point, Projected& pr) const {
  pr.y0 = kSkipped;
  const glm::vec3 rel = point - camera_.eye;
  const float z = glm::dot(rel, forward_);
  if (!(z > camera_.zNear)) return false;
  const glm::vec4 clip = rotationProjection_ * glm::vec4(rel, 1.0f);
  // A point whose projection is off the screen is clipped whole, as
  // OpenGL clips a point by its centre.
  if (!(std::abs(clip.x) <= clip.w && std::abs(clip.y) <= clip.w)) return false;
  // Window coordinates, row 0 at the top (camera.h); the 2x2 pixels whose
  // centres (x + 0.5, y + 0.5) surround (px, py).
  const float px = (clip.x / clip.w * 0.5f + 0.5f) * float(camera_.width);
  const float py = (0.5f - clip.y / clip.w * 0.5f) * float(camera_.height);
  pr.x0 = int(std::floor(px - 0.5f));
  pr.y0 = int(std::floor(py - 0.5f));
  pr.fx = px - (float(pr.x0) + 0.5f);
  pr.fy = py - (float(pr.y0) + 0.5f);
  pr.z = z;
  return true;
}

bool ImpostorSplatter::overMask(const Projected& pr) const {
  for (int y = std::max(pr.y0, 0); y <= std::min(pr.y0 + 1, camera_.height - 1); ++y)
    for (int x = std::max(pr.x0, 0); x <= std::min(pr.x0 + 1, camera_.width - 1); ++x)
      if (mask_->has(size_t(y) * size_t(camera_.width) + size_t(x))) return true;
  return false;
}

bool ImpostorSplatter::mayCover(const Box3f& bounds) const {
  return mask_ ? maskTiles_.mayCover(camera_, bounds)
               : impostorFootprint(camera_, bounds).has_value();
}

void ScreenTiles::reset(int width, int height) {
  width_ = width;
  height_ = height;
  tilesX_ = (width + kTile - 1) / kTile;
  tiles_.assign(size_t(tilesX_) * size_t((height + kTile - 1) / kTile), 0);
}

void ScreenTiles::markList(std::span<const uint32_t> pixels) {
  PixelRows rows(width_);
  for (const uint32_t p : pixels) {
    VS_CHECK(p < uint32_t(width_) * uint32_t(height_));
    const glm::ivec2 xy = rows.at(p);
    tiles_[size_t(xy.y / kTile) * size_t(tilesX_) + size_t(xy.x / kTile)] = 1;
  }
}

void ScreenTiles::markMask(const PixelMask& mask) {
  VS_CHECK(mask.size() == size_t(width_) * size_t(height_));
  markList(mask.pixels());
}

void ScreenTiles::markReach(const Camera& camera, const Impostor& impostor) {
  VS_CHECK(camera.width == width_ && camera.height == height_);
  auto mark = [&](const Box3f& box) {
    const std::optional<glm::ivec4> rect = impostorFootprint(camera, box);
    if (!rect) return;
    for (int ty = rect->y / kTile; ty <= rect->w / kTile; ++ty)
      std::fill_n(
          tiles_.begin() + std::ptrdiff_t(size_t(ty) * size_t(tilesX_) + size_t(rect->x / kTile)),
          rect->z / kTile - rect->x / kTile + 1, uint8_t(1));
  };
  if (impostor.size() == 0) return;
  if (impostor.hasBlockBounds()) {
    for (const Box3f& block : impostor.blockBounds) mark(block);
  } else {
    mark(impostor.box);
  }
}

bool ScreenTiles::any() const {
  return std::find(tiles_.begin(), tiles_.end(), uint8_t(1)) != tiles_.end();
}

bool ScreenTiles::mayCover(const Camera& camera, const Box3f& box) const {
  VS_CHECK(camera.width == width_ && camera.height == height_);
  const std::optional<glm::ivec4> rect = impostorFootprint(camera, box);
  if (!rect) return false;
  for (int ty = rect->y / kTile; ty <= rect->w / kTile; ++ty)
    for (int tx = rect->x / kTile; tx <= rect->z / kTile; ++tx)
      if (tiles_[size_t(ty) * size_t(tilesX_) + size_t(tx)]) return true;
  return false;
}

size_t ImpostorSplatter::draw(const Impostor& impostor, ImageRgb8& out) {
  const Impostor* one[] = {&impostor};
  return draw(one, out);
}

size_t ImpostorSplatter::draw(std::span<const Impostor* const> impostors, ImageRgb8& out,
                              std::vector<size_t>* landedEach) {
  VS_CHECK(out.width == camera_.width && out.height == camera_.height);
  // The impostors that may cover a pixel, their points and blocks laid end
  // to end: point k of impostor i is point firstPoint_[i] + k, its block
  // firstBlock_[i] + k / blockSize[i].
  drawn_.clear();
  firstPoint_.assign(1, 0);
  firstBlock_.assign(1, 0);
  if (landedEach) landedEach->assign(impostors.size(), 0);
  for (size_t i = 0; i < impostors.size(); ++i) {
    const Impostor& imp = *impostors[i];
    if (imp.size() == 0 || !mayCover(imp.box)) continue;
    drawn_.push_back(uint32_t(i));
    const size_t blockSize = imp.hasBlockBounds() ? Impostor::kBlockPoints : 4096;
    firstPoint_.push_back(firstPoint_.back() + imp.size());
    firstBlock_.push_back(firstBlock_.back() + (imp.size() + blockSize - 1) / blockSize);
  }
  if (drawn_.empty()) return 0;
  const size_t blockCount = firstBlock_.back();
  projected_.resize(firstPoint_.back());
  blockBands_.resize(blockCount);
  blockOwner_.resize(blockCount);
  for (size_t d = 0; d < drawn_.size(); ++d)
    std::fill(blockOwner_.begin() + std::ptrdiff_t(firstBlock_[d]),
              blockOwner_.begin() + std::ptrdiff_t(firstBlock_[d + 1]), uint32_t(d));
  const int width = camera_.width, height = camera_.height;
  // Block b of the drawn impostors: its impostor, and its points' range in
  // that impostor.
  struct Block {
    const Impostor* imp;
    size_t offset, first, last;
  };
  auto blockAt = [&](size_t b) {
    const uint32_t d = blockOwner_[b];
    const Impostor* imp = impostors[drawn_[d]];
    const size_t blockSize = imp->hasBlockBounds() ? Impostor::kBlockPoints : 4096;
    const size_t first = (b - firstBlock_[d]) * blockSize;
    return Block{imp, firstPoint_[d], first, std::min(imp->size(), first + blockSize)};
  };
  // 1. Every point projected (in parallel, by blocks): its 2x2 pixels'
  // corner, its offset from that corner's centre and its depth. A block of
  // points (Impostor::blockBounds) wholly out of view, or over none of the
  // pixels the mask lets through, is skipped whole. Per block, the bands its
  // points' rows fall in (first > last: none).
  std::vector<size_t> landed(drawn_.size(), 0);
  std::mutex landedMutex;
  // A few thousand points: both passes on the calling thread (setSerialBelow).
  const bool serial = firstPoint_.back() < serialBelow_;
  const size_t grain = serial ? std::max<size_t>(1, blockCount) : 8;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, blockCount, grain), [&](const auto& blocks) {
    std::vector<std::pair<uint32_t, size_t>> counts;  // (drawn impostor, points landed)
    for (size_t b = blocks.begin(); b < blocks.end(); ++b) {
      const Block blk = blockAt(b);
      int yLo = height, yHi = -2;
      size_t count = 0;
      if (!blk.imp->hasBlockBounds() ||
          mayCover(blk.imp->blockBounds[b - firstBlock_[blockOwner_[b]]])) {
        for (size_t k = blk.first; k < blk.last; ++k) {
          Projected& pr = projected_[blk.offset + k];
          if (project(blk.imp->points[k], pr)) {
            // Over no pixel the mask lets through: it would draw nothing.
            if (mask_ && !overMask(pr)) {
              pr.y0 = kSkipped;
              continue;
            }
            ++count;
            yLo = std::min(yLo, pr.y0);
            yHi = std::max(yHi, pr.y0);
          }
        }
      } else {
        for (size_t k = blk.first; k < blk.last; ++k) projected_[blk.offset + k].y0 = kSkipped;
      }
      blockBands_[b] = yHi < yLo ? glm::ivec2(1, 0)
                                 : glm::ivec2(bandOfRow_[size_t(std::max(yLo, 0))],
                                              bandOfRow_[size_t(std::min(yHi + 1, height - 1))]);
      if (count) {
        if (counts.empty() || counts.back().first != blockOwner_[b])
          counts.emplace_back(blockOwner_[b], 0);
        counts.back().second += count;
      }
    }
    const std::lock_guard<std::mutex> lock(landedMutex);
    for (const auto& [d, c] : counts) landed[d] += c;
  });
  // 2. Depth test in bands of rows, each band in parallel, every band's
  // points in the impostors' order, so a pixel keeps the point of least
  // score and of equals the first, as one pass over them would. 3. Each
  // pixel a point won takes that point's colour seen from the eye.
  const float radius2 = splat_.radius * splat_.radius;
  // Bands first to last as one (serially: each point visited once).
  auto depthTest = [&](int first, int last) {
    const int rowLo = first * height / bands_, rowHi = (last + 1) * height / bands_;
    std::vector<uint32_t>& won = wonScratch_.local();
    won.clear();
    for (size_t b = 0; b < blockCount; ++b) {
      if (last < blockBands_[b].x || first > blockBands_[b].y) continue;
      const Block blk = blockAt(b);
      for (size_t k = blk.offset + blk.first; k < blk.offset + blk.last; ++k) {
        const Projected& pt = projected_[k];
        if (pt.y0 == kSkipped || pt.y0 + 1 < rowLo || pt.y0 >= rowHi) continue;
        for (int y = std::max(pt.y0, rowLo); y <= std::min(pt.y0 + 1, rowHi - 1); ++y)
          for (int x = std::max(pt.x0, 0); x <= std::min(pt.x0 + 1, width - 1); ++x) {
            const float dx = pt.fx - float(x - pt.x0), dy = pt.fy - float(y - pt.y0);
            const float d2 = dx * dx + dy * dy;
            if (d2 > radius2) continue;
            const size_t p = size_t(y) * size_t(width) + size_t(x);
            const float score = splat_.score(pt.z, d2);
            if (!(score < score_[p]) || (mask_ && !mask_->has(p))) continue;
            if (winner_[p] == kNoWinner) won.push_back(uint32_t(p));
            score_[p] = score;
            depth_[p] = pt.z;
            winner_[p] = uint32_t(k);
          }
      }
    }
    for (uint32_t p : won) {
      const uint32_t k = winner_[p];
      const size_t d = size_t(std::upper_bound(firstPoint_.begin(), firstPoint_.end(), size_t(k)) -
                              firstPoint_.begin()) -
                       1;
      out.set(int(p % uint32_t(width)), int(p / uint32_t(width)),
              toBytes(impostors[drawn_[d]]->colourSeenFrom(k - firstPoint_[d], camera_.eye)));
      winner_[p] = kNoWinner;
    }
    std::vector<uint32_t>& touched = touched_[size_t(first)];
    touched.insert(touched.end(), won.begin(), won.end());
  };
  if (serial)
    depthTest(0, bands_ - 1);
  else
    tbb::parallel_for(0, bands_, [&](int band) { depthTest(band, band); });
  size_t total = 0;
  for (size_t d = 0; d < drawn_.size(); ++d) {
    total += landed[d];
    if (landedEach) (*landedEach)[drawn_[d]] = landed[d];
  }
  return total;
}

}  // namespace vistream
