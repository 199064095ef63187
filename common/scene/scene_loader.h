// Loading scenes from files: OBJ, glTF 2.0 (.gltf/.glb) and scene manifests
// (.json, see manifest.h).
//
// Every loader returns a finalized Scene (scene.h) stored relative to a local
// origin at the centre of its bounds, or throws InputError naming the file and
// the line (OBJ) or element (glTF) that is wrong: empty files, NaN/inf or
// unparsable coordinates, coordinates too far from the local origin to store
// as float, faces with fewer than 3 vertices, out-of-range indices, unreadable
// files, JSON nested deeper than kMaxJsonNesting. Degenerate triangles are
// kept and counted in Scene::diagnostics. Loaders are safe on arbitrary bytes:
// no crash, no hang, memory proportional to the input and bounded by
// SceneLimits.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "common/core/error.h"
#include "common/scene/scene.h"

namespace vistream {

// Default limits, chosen on the 24 GiB development machine. A loaded triangle
// costs about 265 bytes at peak: `vistream-server --scene bigcity` (2.59M
// triangles, before any client) and `vistream-scene info` on bigcity and on its
// 126 MB OBJ each peak at 684-688 MB resident (/usr/bin/time -v). 8M triangles,
// three bigcities, is then about 2.1 GB before per-client state, a tenth of the
// machine. Text OBJ costs about 49 bytes per triangle (bigcity.obj), so a
// legitimate 8M-triangle OBJ is about 400 MB; 2 GiB leaves room for glb files
// with embedded images while capping the copies a parser makes of the bytes.
inline constexpr uint64_t kDefaultMaxSceneTriangles = 8'000'000;
inline constexpr uint64_t kDefaultMaxSceneFileBytes = uint64_t(2) << 30;

// What one scene file (or manifest, over all its parts) may make a loader
// allocate. Checked while reading, before the large allocations:
// - maxFileBytes: the size of each file read (the scene file, an OBJ's .mtl, a
//   glTF's external buffers and images);
// - maxTriangles: the triangles the file will produce, counted before building
//   them (OBJ: n-2 per `f` line of n vertices; glTF: per mesh instance, from
//   accessor counts). Vertices are capped at 3 per allowed triangle (OBJ `v`,
//   `vt` and `vn` lines each; glTF POSITION elements per mesh instance): more
//   could not all be used. Face IDs are 32-bit, so at most 2^32-1 triangles
//   whatever the limit.
// Built-in generated scenes are trusted and not limited.
struct SceneLimits {
  uint64_t maxTriangles = kDefaultMaxSceneTriangles;
  uint64_t maxFileBytes = kDefaultMaxSceneFileBytes;
};

// The InputError thrown when a file goes over SceneLimits::maxTriangles (or
// the vertex cap derived from it). The message names the file, the count
// found, the limit and the option that raises it, --max-scene-triangles.
class SceneLimitError : public InputError {
 public:
  SceneLimitError(const std::string& message, uint64_t foundCount, uint64_t limitCount)
      : InputError(InputErrorCode::TooLarge, message), found(foundCount), limit(limitCount) {}
  uint64_t found;  // triangles (or vertices) in the file, or at least this many
  uint64_t limit;  // the limit they exceed, in the same unit
};

// Deepest nesting of JSON arrays and objects accepted in glTF files and
// manifests. Real glTF nests about 8 levels; tinygltf converts `extras` to its
// own values recursively, so 20,000 levels overflow the stack.
inline constexpr size_t kMaxJsonNesting = 256;

// Dispatches on the extension: .obj, .gltf, .glb, .json (manifest).
Scene loadScene(const std::filesystem::path& path, const SceneLimits& limits = {});

// OBJ via tinyobjloader (double precision). Faces keep their `f` line order as
// face IDs; polygons (convex or concave) are triangulated by ear clipping.
// `o`/`g` groups become objects. The .mtl named by `mtllib` is read when present.
Scene loadObj(const std::filesystem::path& path, const SceneLimits& limits = {});

// The same from memory; `displayName` is used in error messages and
// `mtlText` stands in for the .mtl file. Used by the fuzzer and tests.
Scene loadObjFromMemory(std::string_view objText, const std::string& displayName,
                        std::string_view mtlText = {}, const SceneLimits& limits = {});

// glTF 2.0 via tinygltf: the default scene's node hierarchy with transforms
// applied (in double precision), triangle primitives in node traversal order,
// materials (base colour factor and texture), skins and animations kept.
// Objects that are skinned or animated are flagged dynamic. The .glb container
// (header and chunk lengths) and the JSON nesting depth are checked here
// before tinygltf sees the bytes.
Scene loadGltf(const std::filesystem::path& path, const SceneLimits& limits = {});

// A glTF binary (.glb) from memory, e.g. received over the network: checked
// as loadGltf checks a file; `name` stands for the file in errors and as the
// scene's name. Every buffer and image must be inside the bytes: a URI
// naming a file is an InputError (nothing is read from disk).
Scene loadGlbFromMemory(std::string_view bytes, const std::string& name,
                        const SceneLimits& limits = {});

// ---- shared by the loaders ------------------------------------------------------

// The whole file, after checking that it exists, is a regular file (not a
// directory, FIFO or device) and holds at most limits.maxFileBytes bytes.
// Throws InputError naming the file otherwise.
std::string readSceneFile(const std::filesystem::path& path, const SceneLimits& limits);

// Throws InputError naming `name` and the line if `json` nests arrays and
// objects deeper than kMaxJsonNesting (brackets inside strings do not count).
// Says nothing about whether the text is otherwise valid JSON.
void checkJsonNesting(std::string_view json, const std::string& name);

// The triangle limit in effect: limits.maxTriangles, at most 2^32-1.
uint64_t triangleLimit(const SceneLimits& limits);

// The vertex cap: 3 per triangle of triangleLimit(), at most 2^31-1.
uint64_t vertexLimit(const SceneLimits& limits);

// Throws SceneLimitError: "`file`: `found` `unit`, more than the limit of
// `limit`; ... --max-scene-triangles". `unit` is "triangles", "vertices", ...
[[noreturn]] void throwSceneLimit(const std::string& file, uint64_t found, uint64_t limit,
                                  const std::string& unit);

}  // namespace vistream
