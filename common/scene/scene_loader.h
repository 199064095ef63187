// Loading scenes from files: OBJ, glTF 2.0 (.gltf/.glb) and scene manifests
// (.json, see manifest.h).
//
// Every loader returns a finalized Scene (scene.h) stored relative to a local
// origin at the centre of its bounds, or throws InputError naming the file and
// the line (OBJ) or element (glTF) that is wrong: empty files, NaN/inf or
// unparsable coordinates, faces with fewer than 3 vertices, out-of-range
// indices, unreadable files. Degenerate triangles are kept and counted in
// Scene::diagnostics. Loaders are safe on arbitrary bytes: no crash, no hang,
// memory proportional to the input.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "common/scene/scene.h"

namespace vistream {

// Dispatches on the extension: .obj, .gltf, .glb, .json (manifest).
Scene loadScene(const std::filesystem::path& path);

// OBJ via tinyobjloader (double precision). Faces keep their `f` line order as
// face IDs; polygons (convex or concave) are triangulated by ear clipping.
// `o`/`g` groups become objects. The .mtl named by `mtllib` is read when present.
Scene loadObj(const std::filesystem::path& path);

// The same from memory; `displayName` is used in error messages and
// `mtlText` stands in for the .mtl file. Used by the fuzzer and tests.
Scene loadObjFromMemory(std::string_view objText, const std::string& displayName,
                        std::string_view mtlText = {});

// glTF 2.0 via tinygltf: the default scene's node hierarchy with transforms
// applied (in double precision), triangle primitives in node traversal order,
// materials (base colour factor and texture), skins and animations kept.
// Objects that are skinned or animated are flagged dynamic.
Scene loadGltf(const std::filesystem::path& path);

}  // namespace vistream
