#include "common/spatial/free_space.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>

#include "common/raycast/sampled_visibility.h"

namespace vistream {

glm::ivec2 FreeSpace::columnOf(const glm::vec2& xz) const {
  return {int(std::floor((xz.x - origin_.x) / cell_)), int(std::floor((xz.y - origin_.y) / cell_))};
}

std::optional<float> FreeSpace::floorAt(const glm::vec2& xz) const {
  const glm::ivec2 c = columnOf(xz);
  if (!walkable(c.x, c.y)) return std::nullopt;
  return floorHeight(c.x, c.y);
}

std::vector<glm::ivec2> FreeSpace::walkableColumns() const {
  std::vector<glm::ivec2> out;
  out.reserve(walkableCount_);
  for (int k = 0; k < nz_; ++k)
    for (int i = 0; i < nx_; ++i)
      if (walkable_[index(i, k)]) out.emplace_back(i, k);
  return out;
}

FreeSpace FreeSpace::build(const RayQuery& rays, const Box3f& bounds,
                           const FreeSpaceOptions& options) {
  FreeSpace fs;
  if (bounds.empty()) return fs;
  const glm::vec3 ext = bounds.extent();
  const float area = std::max(ext.x, 1e-3f) * std::max(ext.z, 1e-3f);
  fs.cell_ = std::max(options.minCellSize, std::sqrt(area / float(options.maxColumns)));
  fs.nx_ = std::max(1, int(std::ceil(ext.x / fs.cell_)));
  fs.nz_ = std::max(1, int(std::ceil(ext.z / fs.cell_)));
  fs.origin_ = {bounds.lo.x, bounds.lo.z};
  // Steps a viewer takes in stride: half a metre, more on coarse grids so a
  // 30% slope sampled at this resolution stays connected.
  fs.maxStep_ = 0.35f + 0.6f * fs.cell_;
  const size_t n = size_t(fs.nx_) * size_t(fs.nz_);
  std::vector<uint8_t> candidate(n, 0);
  fs.floor_.assign(n, 0.0f);

  const float top = bounds.hi.y + 1.0f, bottom = bounds.lo.y - 1.0f;
  tbb::parallel_for(tbb::blocked_range<int>(0, fs.nz_), [&](const tbb::blocked_range<int>& r) {
    std::vector<Hit> hits;
    for (int k = r.begin(); k < r.end(); ++k) {
      for (int i = 0; i < fs.nx_; ++i) {
        const glm::vec2 c = fs.columnCentre(i, k);
        Ray ray{{c.x, top, c.y}, {0.0f, -1.0f, 0.0f}, 0.0f, top - bottom};
        hits.clear();
        rays.allHits(ray, hits);
        // Walk bottom-up: the lowest upward-facing surface with headroom wins.
        std::optional<float> best;
        for (size_t h = hits.size(); h-- > 0;) {
          const Hit& hit = hits[h];
          const float y = top - hit.t;
          const float len = glm::length(hit.normal);
          const bool up = len > 0.0f && hit.normal.y / len > options.upwardNormalY;
          if (!up) continue;
          // The nearest surface above this floor. A downward-facing surface
          // at the very same height (a box resting on the floor) leaves no
          // headroom at all.
          float ceiling = std::numeric_limits<float>::infinity();
          for (size_t a = 0; a < hits.size(); ++a) {
            if (a == h) continue;
            const float ya = top - hits[a].t;
            const bool aUp = hits[a].normal.y > 0.0f;
            if (ya > y || (ya == y && !aUp)) ceiling = std::min(ceiling, ya);
          }
          if (ceiling - y >= options.headroom) {
            best = y;
            break;
          }
        }
        // A floor inside a closed solid (the ground under a building whose
        // bottom face the vertical ray does not report apart from the ground)
        // is no place to stand: its walls are invisible to vertical rays.
        if (best && insideSolid(rays, {c.x, *best + 1.0f, c.y})) best.reset();
        if (best) {
          candidate[fs.index(i, k)] = 1;
          fs.floor_[fs.index(i, k)] = *best;
        }
      }
    }
  });

  // Keep the viewer radius away from anything that is not floor.
  const int reach = int(std::ceil(options.viewerRadius / fs.cell_ - 0.5f));
  std::vector<uint8_t> eroded = candidate;
  if (reach > 0) {
    for (int k = 0; k < fs.nz_; ++k)
      for (int i = 0; i < fs.nx_; ++i) {
        if (!candidate[fs.index(i, k)]) continue;
        const float h = fs.floor_[fs.index(i, k)];
        for (int dk = -reach; dk <= reach && eroded[fs.index(i, k)]; ++dk)
          for (int di = -reach; di <= reach; ++di) {
            const int ii = i + di, kk = k + dk;
            if (ii < 0 || kk < 0 || ii >= fs.nx_ || kk >= fs.nz_) continue;
            if (!candidate[fs.index(ii, kk)] ||
                std::abs(fs.floor_[fs.index(ii, kk)] - h) >
                    fs.maxStep_ * float(std::max(std::abs(di), std::abs(dk)))) {
              eroded[fs.index(i, k)] = 0;
              break;
            }
          }
      }
  }

  // Largest connected component under the step rule.
  std::vector<int32_t> label(n, -1);
  int32_t bestLabel = -1;
  size_t bestSize = 0;
  int32_t next = 0;
  std::deque<size_t> queue;
  for (size_t s = 0; s < n; ++s) {
    if (!eroded[s] || label[s] >= 0) continue;
    size_t size = 0;
    label[s] = next;
    queue.push_back(s);
    while (!queue.empty()) {
      const size_t c = queue.front();
      queue.pop_front();
      ++size;
      const int ci = int(c % size_t(fs.nx_)), ck = int(c / size_t(fs.nx_));
      const int di[4] = {1, -1, 0, 0}, dk[4] = {0, 0, 1, -1};
      for (int d = 0; d < 4; ++d) {
        const int ii = ci + di[d], kk = ck + dk[d];
        if (ii < 0 || kk < 0 || ii >= fs.nx_ || kk >= fs.nz_) continue;
        const size_t m = fs.index(ii, kk);
        if (!eroded[m] || label[m] >= 0) continue;
        if (std::abs(fs.floor_[m] - fs.floor_[c]) > fs.maxStep_) continue;
        label[m] = next;
        queue.push_back(m);
      }
    }
    if (size > bestSize) {
      bestSize = size;
      bestLabel = next;
    }
    ++next;
  }
  fs.walkable_.assign(n, 0);
  for (size_t s = 0; s < n; ++s) fs.walkable_[s] = label[s] == bestLabel && bestLabel >= 0;
  fs.walkableCount_ = bestSize;
  return fs;
}

}  // namespace vistream
