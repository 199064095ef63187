// Simulated users walking near the viewer, so avatars can be seen without a
// server (`vistream-client --headless --avatars N`).
//
// Every simulated user walks the viewer's own path, which lies in free
// space, turned around at its ends (ping-pong), beside it by up to 0.7 m
// (less where a wall is nearer; left and right alternate). Their roles
// cycle with the index i (k = i / 4 makes later users start farther off):
//   i % 4 == 0: walks ahead of the viewer at the viewer's pace, 6 + 3k m ahead;
//   i % 4 == 1: comes towards the viewer at walking pace from 20 + 6k m ahead;
//   i % 4 == 2: runs (3.6 m/s), starting 3 + 2k m behind the viewer;
//   i % 4 == 3: stands 10 + 5k m ahead of the viewer's start, facing back.
// Clip phases are offset per user so they do not move in step.
//
// Thread safety: immutable after construction.
#pragma once

#include <vector>

#include "client/avatar/avatar_view.h"
#include "common/generate/path.h"
#include "common/raycast/ray_query.h"

namespace vistream {

class LocalCrowd {
 public:
  // `path` in file coordinates, `origin` the scene's local origin; `rays`
  // (may be null) keeps the sideways offset out of walls.
  LocalCrowd(const std::vector<PathSample>& path, const glm::dvec3& origin, size_t count,
             const RayQuery* rays = nullptr);
  size_t size() const { return count_; }
  // Every simulated user at time t (seconds of the path's clock).
  std::vector<AvatarState> at(double t) const;

 private:
  // Position (eye, local) and unit horizontal direction of travel at arc
  // length s along the ping-pong path.
  void along(double s, glm::vec3& eye, glm::vec3& heading) const;
  double viewerArc(double t) const;  // the viewer's arc length at time t
  std::vector<double> times_, arc_;  // per sample
  std::vector<glm::vec3> eyes_;      // per sample, local
  size_t count_ = 0;
  const RayQuery* rays_ = nullptr;
};

}  // namespace vistream
