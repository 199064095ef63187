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
#include <string>

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

// The manifest format for people: the text `vistream-scene info --help`
// shows (README.md, "Scene manifests", says the same).
std::string manifestFormatHelp();

// A dynamic object taller than this (metres) is almost certainly in the
// wrong unit: the dynamic objects a walkthrough shows are avatars, animals
// and vehicles, and the tallest of those (a giraffe, about 6 m; a
// double-decker bus, 4.4 m) stay below it, while a person or an animal
// modelled in centimetres comes out at 50 m and more.
constexpr double kMaxPlausibleDynamicHeight = 10.0;

// Logs one warning per dynamic object of `scene` taller than
// kMaxPlausibleDynamicHeight, naming `where` (the file, or the manifest
// entry) and the manifest's "scale" key that fixes it. Returns how many.
size_t warnImplausiblyLargeDynamicObjects(const Scene& scene, const std::string& where);

// Throws InputError naming `path` unless the file starts like a Radiance
// HDR image ("#?RADIANCE" or "#?RGBE" on its first line).
void checkRadianceHeader(const std::filesystem::path& path, const std::string& where);

}  // namespace vistream
