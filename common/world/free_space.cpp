#include "common/world/free_space.h"

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <deque>
#include <limits>

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

namespace {

// A floor is a horizontal surface a viewer can stand on. Winding is used
// only where Solids trusts it: the face of a closed, consistently oriented
// solid is a floor only when its outside is above it (an outward solid's
// up-facing face, an inward solid's down-facing one); the underside of a
// closed box has solid above it, whichever column grazes it. Every other
// face (open sheets, non-manifold or inconsistently wound meshes, the
// assumed ground plane) is two-sided.
bool isFloor(const Hit& h, const Solids& solids, float upwardNormalY) {
  const float len = glm::length(h.normal);
  if (!(len > 0.0f) || std::abs(h.normal.y) / len <= upwardNormalY) return false;
  if (!h.valid()) return true;
  const uint32_t c = solids.componentOf(h.triangle);
  if (c == kNoHit) return true;
  switch (solids.components()[c].kind) {
    case SolidClass::ClosedOutward:
      return h.normal.y > 0.0f;
    case SolidClass::ClosedInward:
      return h.normal.y < 0.0f;
    default:
      return true;
  }
}

// A surface at the very same height as a floor counts as a ceiling when it
// belongs to another component that rises above the floor (a box resting on
// it), not when it is a coplanar sheet or the same mesh (a ray through a
// shared edge).
bool tieIsCeiling(const Solids& solids, const Hit& floor, const Hit& other, float y) {
  if (!other.valid()) return false;  // the assumed ground plane is a sheet
  const uint32_t c = solids.componentOf(other.triangle);
  if (c == kNoHit || (floor.valid() && solids.componentOf(floor.triangle) == c)) return false;
  return solids.components()[c].bounds.hi.y > y;
}

}  // namespace

FreeSpace FreeSpace::build(const RayQuery& rays, const Solids& solids, const Box3f& bounds,
                           const FreeSpaceOptions& options) {
  FreeSpace fs;
  fs.stats_.solids = solids.census();
  fs.headroom_ = options.headroom;
  fs.viewerRadius_ = options.viewerRadius;
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

  const std::optional<float> ground = options.groundY;
  const float top = std::max(bounds.hi.y, ground.value_or(bounds.hi.y)) + 1.0f;
  const float bottom = std::min(bounds.lo.y, ground.value_or(bounds.lo.y)) - 1.0f;
  std::atomic<size_t> noFloor{0}, insideCount{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, fs.nz_), [&](const tbb::blocked_range<int>& r) {
    std::vector<Hit> hits;
    size_t rowNoFloor = 0, rowInside = 0;
    for (int k = r.begin(); k < r.end(); ++k) {
      for (int i = 0; i < fs.nx_; ++i) {
        const glm::vec2 c = fs.columnCentre(i, k);
        Ray ray{{c.x, top, c.y}, {0.0f, -1.0f, 0.0f}, 0.0f, top - bottom};
        hits.clear();
        rays.allHits(ray, hits);
        if (ground) {
          Hit plane;  // no triangle: the assumed ground plane
          plane.t = top - *ground;
          plane.normal = {0.0f, 1.0f, 0.0f};
          hits.insert(std::upper_bound(hits.begin(), hits.end(), plane,
                                       [](const Hit& a, const Hit& b) { return a.t < b.t; }),
                      plane);
        }
        // Walk bottom-up: the lowest floor with headroom and air above it
        // wins; a floor inside a solid is skipped and the next one up tried.
        std::optional<float> best;
        bool headroomSeen = false;
        for (size_t h = hits.size(); h-- > 0;) {
          const Hit& hit = hits[h];
          if (!isFloor(hit, solids, options.upwardNormalY)) continue;
          const float y = top - hit.t;
          // The nearest surface above this floor. A solid resting on the
          // floor at the very same height leaves no headroom at all.
          float ceiling = std::numeric_limits<float>::infinity();
          for (size_t a = 0; a < hits.size(); ++a) {
            if (a == h) continue;
            const float ya = top - hits[a].t;
            if (ya > y || (ya == y && tieIsCeiling(solids, hit, hits[a], y)))
              ceiling = std::min(ceiling, ya);
          }
          if (ceiling - y < options.headroom) continue;
          headroomSeen = true;
          // A floor inside a solid (the ground under a building whose
          // bottom face the vertical ray does not report apart from the
          // ground) is no place to stand: its walls are invisible to
          // vertical rays.
          if (!solids.inside(rays, {c.x, y + 1.0f, c.y})) {
            best = y;
            break;
          }
        }
        if (best) {
          candidate[fs.index(i, k)] = 1;
          fs.floor_[fs.index(i, k)] = *best;
        } else {
          ++(headroomSeen ? rowInside : rowNoFloor);
        }
      }
    }
    noFloor += rowNoFloor;
    insideCount += rowInside;
  });
  fs.stats_.columns = n;
  fs.stats_.noFloor = noFloor;
  fs.stats_.insideSolid = insideCount;
  fs.stats_.floors = n - noFloor - insideCount;

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
  size_t kept = 0;
  for (size_t s = 0; s < n; ++s) kept += eroded[s];
  fs.stats_.nearObstacle = fs.stats_.floors - kept;
  fs.stats_.disconnected = kept - bestSize;
  return fs;
}

std::string FreeSpace::emptyReason() const {
  if (walkableCount_ > 0) return {};
  const FreeSpaceStats& s = stats_;
  if (s.columns == 0) return "the scene has no static geometry";
  std::string why;
  if (s.floors == 0 && s.insideSolid == 0) {
    why = fmt::format(
        "none of its {} columns has a horizontal surface with {:g} m of headroom above it",
        s.columns, headroom_);
  } else if (s.floors == 0 && s.noFloor == 0) {
    why = fmt::format("every column's point 1 m above the floor is inside a solid ({} columns)",
                      s.columns);
  } else if (s.floors == 0) {
    why = fmt::format(
        "of its {} columns, {} have no horizontal surface with {:g} m of headroom and {} have "
        "their point 1 m above the floor inside a solid",
        s.columns, s.noFloor, headroom_, s.insideSolid);
  } else {
    why = fmt::format(
        "all {} columns with a floor lie within the viewer radius ({:g} m) of an "
        "obstacle or a step",
        s.floors, viewerRadius_);
  }
  auto faces = [&](SolidClass c) { return s.solids.faces[size_t(c)]; };
  std::vector<std::string> winding;
  if (faces(SolidClass::Inconsistent) > 0)
    winding.push_back(fmt::format("{} faces are in inconsistently wound meshes",
                                  faces(SolidClass::Inconsistent)));
  if (faces(SolidClass::NonManifold) > 0)
    winding.push_back(
        fmt::format("{} faces are in non-manifold meshes", faces(SolidClass::NonManifold)));
  if (faces(SolidClass::ClosedInward) > 0)
    winding.push_back(
        fmt::format("{} faces are in closed meshes wound inward", faces(SolidClass::ClosedInward)));
  for (const std::string& w : winding) why += "; " + w;
  return why;
}

}  // namespace vistream
