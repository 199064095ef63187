// Whether an impostor's points cover every pixel where its own faces are
// the first thing seen: the oracle of the no-holes tests on whole scenes.
#pragma once

#include <cstddef>
#include <vector>

#include "client/render/camera.h"
#include "client/render/image.h"
#include "client/render/impostor_splat.h"
#include "common/impostor/impostor.h"
#include "common/raycast/ray_query.h"

namespace vistream::testing {

struct FaceCoverage {
  size_t seen = 0;       // pixels whose centre ray first meets one of the faces
  size_t uncovered = 0;  // of those, the ones no point covers
};

// Ray casts each camera's pixel centres against the whole scene (`rays`)
// and splats the impostor; `faces[t]` marks the impostor's triangles.
inline FaceCoverage faceCoverage(const RayQuery& rays, const std::vector<bool>& faces,
                                 const Impostor& imp, const std::vector<Camera>& cameras) {
  FaceCoverage sum;
  for (const Camera& c : cameras) {
    ImpostorSplatter splatter;
    splatter.begin(c);
    ImageRgb8 image(c.width, c.height);
    splatter.draw(imp, image);
    for (int y = 0; y < c.height; ++y)
      for (int x = 0; x < c.width; ++x) {
        const Hit h = rays.firstHit(
            Ray{c.eye, c.rayDirection(float(x) + 0.5f, float(y) + 0.5f), 0.0f, 1e30f});
        if (!h.valid() || !faces[h.triangle]) continue;
        ++sum.seen;
        sum.uncovered += !splatter.covered(x, y);
      }
  }
  return sum;
}

}  // namespace vistream::testing
