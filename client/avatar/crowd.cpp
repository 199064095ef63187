#include "client/avatar/crowd.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace vistream {
namespace {

constexpr float kSideOffset = 0.7f;  // metres beside the path
constexpr float kWallClearance = 0.3f;
constexpr double kRunSpeed = 3.6;  // m/s

double yawOf(const glm::vec3& heading) {
  // View direction (-sin yaw, 0, -cos yaw) along the heading.
  return glm::degrees(std::atan2(-double(heading.x), -double(heading.z)));
}

}  // namespace

LocalCrowd::LocalCrowd(const std::vector<PathSample>& path, const glm::dvec3& origin, size_t count,
                       const RayQuery* rays)
    : count_(count), rays_(rays) {
  double s = 0.0;
  for (size_t i = 0; i < path.size(); ++i) {
    const glm::vec3 eye(path[i].position - origin);
    if (i > 0) s += glm::length(eye - eyes_.back());
    times_.push_back(path[i].t);
    eyes_.push_back(eye);
    arc_.push_back(s);
  }
}

double LocalCrowd::viewerArc(double t) const {
  if (times_.empty()) return 0.0;
  const size_t k = size_t(std::upper_bound(times_.begin(), times_.end(), t) - times_.begin());
  if (k == 0) return arc_.front();
  if (k >= times_.size()) return arc_.back();
  const double dt = times_[k] - times_[k - 1];
  const double f = dt > 0.0 ? (t - times_[k - 1]) / dt : 0.0;
  return arc_[k - 1] + f * (arc_[k] - arc_[k - 1]);
}

void LocalCrowd::along(double s, glm::vec3& eye, glm::vec3& heading) const {
  heading = glm::vec3(0.0f, 0.0f, -1.0f);
  if (eyes_.empty()) {
    eye = glm::vec3(0.0f);
    return;
  }
  const double length = arc_.back();
  if (!(length > 1e-3)) {
    eye = eyes_.front();
    return;
  }
  // Ping-pong: s in [0, 2L) folds back from the far end.
  double u = std::fmod(s, 2.0 * length);
  if (u < 0.0) u += 2.0 * length;
  const bool back = u > length;
  if (back) u = 2.0 * length - u;
  size_t k = size_t(std::upper_bound(arc_.begin(), arc_.end(), u) - arc_.begin());
  k = std::clamp<size_t>(k, 1, arc_.size() - 1);
  // Skip zero-length steps (a viewer standing still) for the heading.
  size_t a = k - 1, b = k;
  while (b + 1 < arc_.size() && arc_[b] - arc_[a] < 1e-4) ++b;
  const double span = arc_[b] - arc_[a];
  const double f = span > 0.0 ? std::clamp((u - arc_[a]) / span, 0.0, 1.0) : 0.0;
  eye = eyes_[a] + float(f) * (eyes_[b] - eyes_[a]);
  glm::vec3 d = eyes_[b] - eyes_[a];
  d.y = 0.0f;
  if (glm::length(d) > 1e-6f) heading = glm::normalize(d) * (back ? -1.0f : 1.0f);
}

std::vector<AvatarState> LocalCrowd::at(double t) const {
  std::vector<AvatarState> out;
  const double viewer = viewerArc(t), start = viewerArc(times_.empty() ? 0.0 : times_.front());
  const double t0 = times_.empty() ? 0.0 : times_.front();
  for (size_t i = 0; i < count_; ++i) {
    const double k = double(i / 4);
    double s = 0.0, speed = 0.0;
    bool facingBack = false;
    switch (i % 4) {
      case 0:  // ahead, at the viewer's pace
        s = viewer + 6.0 + 3.0 * k;
        speed = -1.0;  // measured below
        break;
      case 1:  // oncoming
        s = start + 20.0 + 6.0 * k - kWalkingSpeed * (t - t0);
        speed = kWalkingSpeed;
        facingBack = true;
        break;
      case 2:  // running past
        s = start - 3.0 - 2.0 * k + kRunSpeed * (t - t0);
        speed = kRunSpeed;
        break;
      default:  // standing
        s = start + 10.0 + 5.0 * k;
        speed = 0.0;
        facingBack = true;
        break;
    }
    if (speed < 0.0) {  // the viewer's pace over the last tenth of a second
      speed = std::abs(viewer - viewerArc(t - 0.1)) / 0.1;
    }
    glm::vec3 eye, heading;
    along(s, eye, heading);
    // Beside the path (the side taken along the path's direction), clear of walls.
    const glm::vec3 side = glm::vec3(-heading.z, 0.0f, heading.x) * ((i % 2 == 0) ? 1.0f : -1.0f);
    if (facingBack) heading = -heading;
    float offset = kSideOffset;
    if (rays_) {
      const Hit wall = rays_->firstHit(Ray{eye, side, 0.0f, kSideOffset + kWallClearance});
      if (wall.triangle != kNoHit) offset = std::max(0.0f, wall.t - kWallClearance);
    }
    AvatarState a;
    a.id = uint32_t(i + 1);
    a.eye = eye + side * offset;
    a.yawDeg = float(yawOf(heading));
    a.speed = float(speed);
    a.phase = float(t - t0 + 0.37 * double(i));
    out.push_back(a);
  }
  return out;
}

}  // namespace vistream
