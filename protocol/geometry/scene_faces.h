// Every face of a scene as a Geometry message carries it: its triangles (the
// corners of every static and dynamic object's triangles with that face ID,
// in the source's order), its material and, when the scene's static
// triangles have baked lighting, their colour grids. The streaming server
// keeps one of these per face; the impostor bake encodes the far field it
// replaces with them to compare bytes.
#pragma once

#include <vector>

#include "common/core/box.h"
#include "common/light/lighting.h"
#include "common/scene/scene.h"
#include "protocol/geometry/geometry_codec.h"

namespace vistream::wire {

// Index = face ID (scene.faceCount entries). `lighting`: the grids of the
// scene's static triangles in flattenScene(scene, true) order, or null for
// faces without colours. `boxes`, when given, receives each face's bounds.
std::vector<FaceTriangles> sceneFaces(const Scene& scene, const LightingGrid* lighting,
                                      std::vector<Box3f>* boxes = nullptr);

}  // namespace vistream::wire
