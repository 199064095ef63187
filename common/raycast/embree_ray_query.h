// Embree-specific extras of the Embree back end (makeEmbreeRayQuery is
// declared in ray_query.h with the other back ends).
#pragma once

#include <cstdint>

namespace vistream {

// Number of errors Embree has reported through vistream's device error
// handler since the process started, over every EmbreeRayQuery. Each error is
// also logged with spdlog at error level. Thread-safe.
uint64_t embreeErrorCount();

}  // namespace vistream
