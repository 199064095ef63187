// Scene manifests: one JSON file naming what makes up a scene.
//
//   {
//     "name": "harbour walk",                       // optional, default: file stem
//     "geometry": [                                 // required, at least one entry
//       "city.obj",                                 // a path (relative to the manifest)
//       {"file": "Fox.glb", "dynamic": true,        // or an object: "dynamic" marks every
//        "name": "fox", "translate": [0, 0, 5],     // object of the file dynamic; "name"
//        "scale": 0.01}                             // prefixes object names; translate/scale
//     ],                                            // place the file in the scene (metres)
//     "environment": {                              // optional
//       "hdr": "sky.hdr",                           // equirectangular Radiance HDR
//       "sky": "auto" | "open" | "none",            // default "auto": derived from geometry
//       "sky_color": [0.55, 0.7, 0.9]
//     },
//     "near_field_radius": 150                      // metres, the client's near-field d
//   }
//
// Face IDs run over the geometry files in the order listed: the first file's
// faces are 0..n0-1, the second's n0..n0+n1-1, and so on.
// Unknown keys are rejected (a typo must not silently change a scene).
#pragma once

#include <filesystem>

#include "common/scene/scene.h"
#include "common/scene/scene_loader.h"

namespace vistream {

// Loads a manifest and every file it names. Throws InputError naming the
// manifest and the key or entry that is wrong. `limits` bound each file read
// and the scene as a whole: the triangles of all parts together may not
// exceed limits.maxTriangles (each part is loaded with what the parts before
// it left, so it fails before building more).
Scene loadManifest(const std::filesystem::path& path, const SceneLimits& limits = {});

// Appends `part` to `scene`, offsetting face IDs by scene.faceCount and
// re-expressing positions relative to a common local origin.
void appendScene(Scene& scene, Scene part);

}  // namespace vistream
