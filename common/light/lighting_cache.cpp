#include "common/light/lighting_cache.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <span>

#include "common/core/atomic_file.h"
#include "common/core/error.h"
#include "common/light/texture.h"

namespace vistream {
namespace {

constexpr char kMagic[8] = {'V', 'S', 'L', 'I', 'G', 'H', 'T', '1'};
// Bump when the bake's arithmetic changes, so old files are not read.
constexpr uint64_t kBakeVersion = 3;

struct Fnv {
  uint64_t h = 1469598103934665603ull;
  void bytes(const void* p, size_t n) {
    const auto* b = static_cast<const uint8_t*>(p);
    for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  }
  template <class T>
  void value(const T& v) {
    bytes(&v, sizeof(T));
  }
  void text(const std::string& s) {
    value(uint64_t(s.size()));
    bytes(s.data(), s.size());
  }
};

void fileStamp(Fnv& f, const std::filesystem::path& p) {
  std::error_code ec;
  f.text(p.filename().string());
  const auto size = std::filesystem::file_size(p, ec);
  f.value(uint64_t(ec ? 0 : size));
  const auto time = std::filesystem::last_write_time(p, ec);
  f.value(int64_t(ec ? 0 : time.time_since_epoch().count()));
}

std::optional<LightingGrid> readCache(const std::filesystem::path& file, uint64_t key,
                                      size_t triangles) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return std::nullopt;
  auto fail = [&](const char* why) -> std::optional<LightingGrid> {
    spdlog::warn("lighting cache {}: {}; baking again", file.string(), why);
    return std::nullopt;
  };
  char magic[8];
  uint64_t head[3];
  if (!in.read(magic, 8) || !in.read(reinterpret_cast<char*>(head), sizeof(head)))
    return fail("cut off");
  if (std::memcmp(magic, kMagic, 8) != 0) return fail("not a lighting cache");
  if (head[0] != key || head[1] != triangles) return fail("for another scene or options");
  const uint64_t colours = head[2];
  if (colours > uint64_t(triangles) * LightingGrid::pointsOf(255)) return fail("too many colours");
  LightingGrid g;
  g.level.resize(triangles);
  g.colours.resize(size_t(colours));
  if (!in.read(reinterpret_cast<char*>(g.level.data()), std::streamsize(triangles)) ||
      !in.read(reinterpret_cast<char*>(g.colours.data()), std::streamsize(3 * colours)))
    return fail("cut off");
  uint64_t checksum = 0;
  if (!in.read(reinterpret_cast<char*>(&checksum), 8)) return fail("cut off");
  Fnv f;
  f.bytes(magic, 8);
  f.bytes(head, sizeof(head));
  f.bytes(g.level.data(), g.level.size());
  f.bytes(g.colours.data(), 3 * g.colours.size());
  if (f.h != checksum) return fail("checksum mismatch");
  g.first.resize(triangles);
  uint64_t at = 0;
  for (size_t t = 0; t < triangles; ++t) {
    if (g.level[t] == 0) return fail("a level of 0");
    g.first[t] = uint32_t(at);
    at += LightingGrid::pointsOf(g.level[t]);
  }
  if (at != colours) return fail("levels and colours disagree");
  return g;
}

bool writeCache(const std::filesystem::path& file, uint64_t key, const LightingGrid& g) {
  std::error_code ec;
  std::filesystem::create_directories(file.parent_path(), ec);
  const uint64_t head[3] = {key, g.level.size(), g.colours.size()};
  Fnv f;
  f.bytes(kMagic, 8);
  f.bytes(head, sizeof(head));
  f.bytes(g.level.data(), g.level.size());
  f.bytes(g.colours.data(), 3 * g.colours.size());
  auto bytesOf = [](const void* p, size_t n) {
    return std::span<const uint8_t>(static_cast<const uint8_t*>(p), n);
  };
  // Several processes (pods on one volume) may write the same cache at once:
  // each writes its own temporary, and the last rename wins with a whole file.
  try {
    AtomicFile out(file);
    out.write(bytesOf(kMagic, 8));
    out.write(bytesOf(head, sizeof(head)));
    out.write(bytesOf(g.level.data(), g.level.size()));
    out.write(bytesOf(g.colours.data(), 3 * g.colours.size()));
    out.write(bytesOf(&f.h, 8));
    out.commit();
  } catch (const InputError&) {
    return false;
  }
  return true;
}

}  // namespace

std::filesystem::path defaultLightingCacheDir() {
  if (const char* d = std::getenv("VISTREAM_CACHE_DIR"); d && *d) return d;
  if (const char* d = std::getenv("XDG_CACHE_HOME"); d && *d)
    return std::filesystem::path(d) / "vistream";
  if (const char* home = std::getenv("HOME"); home && *home)
    return std::filesystem::path(home) / ".cache" / "vistream";
  return std::filesystem::temp_directory_path() / "vistream-cache";
}

uint64_t lightingKey(const Scene& scene, const FlatTriangles& triangles,
                     const LightingOptions& options) {
  Fnv f;
  f.value(kBakeVersion);
  f.value(uint64_t(triangles.size()));
  f.bytes(triangles.positions.data(), triangles.positions.size() * sizeof(glm::vec3));
  for (const Material& m : scene.materials) {
    f.value(m.diffuse);
    f.value(m.unassigned);
    f.text(m.baseColorTexture);
    if (m.baseColorImage) f.bytes(m.baseColorImage->data(), m.baseColorImage->size());
    if (const auto file = materialTexturePath(scene, m); !file.empty()) fileStamp(f, file);
  }
  // What the textures are sampled by: each static triangle's material and
  // texture coordinates.
  for (const Object& o : scene.objects) {
    if (o.dynamic) continue;
    f.bytes(o.mesh.materials.data(), o.mesh.materials.size() * sizeof(uint32_t));
    f.bytes(o.mesh.texcoords.data(), o.mesh.texcoords.size() * sizeof(glm::vec2));
    if (!o.mesh.texcoords.empty())
      f.bytes(o.mesh.triangles.data(), o.mesh.triangles.size() * sizeof(glm::uvec3));
  }
  const Environment& e = scene.environment;
  if (!e.hdrImage.empty()) fileStamp(f, e.hdrImage);
  f.value(e.skyColor);
  f.value(options.sunDirection.value_or(e.sunDirection));
  f.value(options.sunIntensity.value_or(e.sunIntensity));
  f.value(options.spacing);
  f.value(options.maxLevel);
  f.value(options.aoRays);
  f.value(options.aoDistance);
  f.value(options.ambient);
  f.value(options.sunShadows);
  f.value(options.tolerance);
  f.value(options.colourStep);
  return f.h;
}

LightingLoad loadOrBakeLighting(const Scene& scene, const FlatTriangles& triangles,
                                const EnvironmentLight& environment, const LightingOptions& options,
                                const std::filesystem::path& dir, bool progress) {
  LightingLoad out;
  uint64_t key = 0;
  if (!dir.empty()) {
    key = lightingKey(scene, triangles, options);
    std::string name = scene.name.empty() ? "scene" : scene.name;
    for (char& c : name)
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
    out.file = dir / fmt::format("{}-{:016x}.light", name, key);
    if (auto g = readCache(out.file, key, triangles.size())) {
      out.grid = std::move(*g);
      out.fromCache = true;
      spdlog::info("lighting read from {}", out.file.string());
      return out;
    }
  }
  const auto rays = makeEmbreeRayQuery(triangles);  // a cache hit needs none
  out.grid = bakeLighting(scene, triangles, *rays, environment, options, &out.stats, progress);
  spdlog::info("lighting baked in {:.2f} s ({} points, {} rays)", out.stats.seconds,
               out.stats.points, out.stats.aoRays + out.stats.shadowRays);
  if (!dir.empty() && !writeCache(out.file, key, out.grid)) {
    spdlog::warn("cannot write the lighting cache {}; the next start bakes again",
                 out.file.string());
    out.file.clear();
  }
  return out;
}

SceneLighting lightScene(const Scene& scene, const FlatTriangles& triangles,
                         const LightingOptions& options, const std::filesystem::path& cacheDir,
                         bool progress) {
  const EnvironmentLight light = EnvironmentLight::of(scene.environment);
  SceneLighting out;
  out.backdrop = backdropOf(scene, light, options);
  out.environment = light.source();
  out.load = loadOrBakeLighting(scene, triangles, light, options, cacheDir, progress);
  return out;
}

}  // namespace vistream
