// The viewpoint rule of the PVS contract (server/visibility/epsilon_pvs.h)
// for sampled ground truth: unserved viewpoints (inside solids, or on the
// surface of closed ones) are skipped.
#pragma once

#include <functional>
#include <memory>

#include "common/raycast/sampled_visibility.h"
#include "common/world/solids.h"

namespace vistream::testing {

// A skipViewpoint rule that owns the solids of `triangles`; `rays` must
// answer over the same triangles and outlive the rule.
inline std::function<bool(const glm::vec3&)> unservedViewpointRule(const FlatTriangles& triangles,
                                                                   const RayQuery& rays) {
  auto solids = std::make_shared<const Solids>(Solids::build(triangles));
  return [solids, &rays](const glm::vec3& p) { return solids->unservedViewpoint(rays, p); };
}

}  // namespace vistream::testing
