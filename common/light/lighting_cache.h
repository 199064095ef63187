// Baked lighting kept on disk, so a scene is baked once and every later
// start (server or local client) reads it back.
//
// Where: `dir`/<scene name>-<key>.light, where the key is a 64-bit hash of
// everything the bake reads: the static triangles with their materials and
// texture coordinates, the materials (colours; texture files by name, size
// and modification time; images inside the scene file by their bytes), the
// environment (HDR file name, size and modification time, sky colour, sun)
// and the LightingOptions, plus the bake's version. A changed scene or option therefore never reads
// a stale bake; it bakes again under a new name. The default directory is $VISTREAM_CACHE_DIR, else
// $XDG_CACHE_HOME/vistream, else ~/.cache/vistream (a scene's own folder may be read-only, as
// ../shared/data is).
//
// File: "VSLIGHT1", the key, triangle and colour counts (uint64, little
// endian), the levels (one byte a triangle), the colours (3 bytes each), an
// FNV-1a checksum of all before it. Written to a temporary name and renamed,
// so a reader never sees a torn file; a file that fails any check is ignored
// (a warning) and baked again.
//
// Thread safety: free functions; concurrent processes may race to write the
// same bake, and the last rename wins with identical bytes.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

#include "common/light/lighting.h"

namespace vistream {

std::filesystem::path defaultLightingCacheDir();

struct LightingLoad {
  LightingGrid grid;
  bool fromCache = false;
  std::filesystem::path file;  // read or written; empty when caching is off
  LightingStats stats;         // of the bake (zero when read from the cache)
};

// Reads the bake from `dir` if there, else bakes (bakeLighting, over an
// Embree query of `triangles` built only then) and writes it there. An empty
// `dir` bakes without caching; a directory that cannot be written only costs
// a warning.
LightingLoad loadOrBakeLighting(const Scene& scene, const FlatTriangles& triangles,
                                const EnvironmentLight& environment, const LightingOptions& options,
                                const std::filesystem::path& dir, bool progress = false);

// A scene's whole lighting: the grids of `triangles` (its static triangles,
// flattenScene(scene, true)) through the cache, and its backdrop, lit by its
// environment (EnvironmentLight::of; throws InputError for an unreadable HDR).
struct SceneLighting {
  LightingLoad load;
  Backdrop backdrop;
  std::string environment;  // EnvironmentLight::source()
};
SceneLighting lightScene(const Scene& scene, const FlatTriangles& triangles,
                         const LightingOptions& options, const std::filesystem::path& cacheDir,
                         bool progress = false);

// The cache key of a bake (exposed for tests).
uint64_t lightingKey(const Scene& scene, const FlatTriangles& triangles,
                     const LightingOptions& options);

}  // namespace vistream
