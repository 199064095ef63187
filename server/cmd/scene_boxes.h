// Boxes given on the command line in file coordinates (--cell, --region):
// parsed and checked before any scene loads, then moved into a scene's
// local frame, with a warning when they miss the scene.
#pragma once

#include <spdlog/spdlog.h>

#include <string>

#include "common/core/box.h"
#include "common/core/error.h"
#include "common/core/parse.h"
#include "common/scene/scene.h"

namespace vistream {

// A box "x0,y0,z0,x1,y1,z1" in file coordinates, given as `option`.
inline Box3d parseFileBox(const std::string& text, const char* option) {
  const auto v = parseNumberList(text, 6, option);
  if (v[0] > v[3] || v[1] > v[4] || v[2] > v[5])
    throwInputError(InputErrorCode::BadArgument,
                    "{}: expected x0,y0,z0,x1,y1,z1 with x0<=x1, y0<=y1, z0<=z1, got '{}'", option,
                    text);
  return Box3d({v[0], v[1], v[2]}, {v[3], v[4], v[5]});
}

inline Box3f toLocal(const Scene& scene, const Box3d& fileBox) {
  return Box3f(scene.toLocal(fileBox.lo), scene.toLocal(fileBox.hi));
}

// A box that misses the scene's bounds sees nothing of it, or only its
// outside: worth a word, since a typo in one coordinate does that.
inline void warnIfOutsideScene(const Scene& scene, const Box3d& fileBox, const char* option,
                               const std::string& text) {
  const Box3d b = scene.fileBounds();
  if (b.empty() || fileBox.overlaps(b)) return;
  spdlog::warn(
      "{} {} lies outside the scene's bounds ({:.3f},{:.3f},{:.3f} .. {:.3f},{:.3f},{:.3f}, file "
      "coordinates)",
      option, text, b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z);
}

}  // namespace vistream
