// Default batched queries: one single-ray query per element. Back ends with a
// packet or stream path (Embree) override these.
#include "common/raycast/ray_query.h"

#include "common/core/check.h"

namespace vistream {

void RayQuery::firstHits(std::span<const Ray> rays, std::span<Hit> hits) const {
  VS_CHECK_EQ(rays.size(), hits.size());
  for (size_t i = 0; i < rays.size(); ++i) hits[i] = firstHit(rays[i]);
}

void RayQuery::occludedMany(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
  VS_CHECK_EQ(rays.size(), occluded.size());
  for (size_t i = 0; i < rays.size(); ++i) occluded[i] = this->occluded(rays[i]) ? 1 : 0;
}

}  // namespace vistream
