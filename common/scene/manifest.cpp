#include "common/scene/manifest.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "common/core/error.h"
#include "common/scene/scene_loader.h"

namespace vistream {
namespace {

using nlohmann::json;

glm::dvec3 readVec3(const json& j, const std::string& where) {
  if (!j.is_array() || j.size() != 3 || !j[0].is_number() || !j[1].is_number() || !j[2].is_number())
    throwInputError("{}: expected an array of three numbers", where);
  glm::dvec3 v(j[0].get<double>(), j[1].get<double>(), j[2].get<double>());
  if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
    throwInputError("{}: numbers must be finite", where);
  return v;
}

void rejectUnknownKeys(const json& j, std::initializer_list<const char*> known,
                       const std::string& where) {
  for (const auto& [key, value] : j.items()) {
    bool ok = false;
    for (const char* k : known) ok = ok || key == k;
    if (!ok) throwInputError("{}: unknown key '{}'", where, key);
  }
}

}  // namespace

std::string manifestFormatHelp() {
  return R"(Scene manifests: a SCENE may be a .json manifest naming what makes up a scene.
  {
    "name": "harbour walk",              optional; default: the file's stem
    "geometry": [                        required, at least one entry, in face-ID order
      "city.obj",                        a path relative to the manifest (.obj, .gltf, .glb)
      {"file": "Fox.glb",                or an object with
       "dynamic": true,                    every object of the file moves (avatars, animals)
       "name": "fox",                      prefix of the file's object names
       "translate": [0, 0, 5],             metres, applied after scale
       "scale": 0.01}                      positive; 0.01 for a file modelled in centimetres
    ],
    "environment": {                     optional
      "hdr": "sky.hdr",                    equirectangular Radiance HDR (#?RADIANCE header)
      "sky": "auto",                       auto (from the geometry), open or none
      "sky_color": [0.55, 0.7, 0.9],       linear RGB (the analytic sky's zenith without an hdr)
      "sun": {"direction": [0.35, 0.85, 0.4],  towards the sun (normalised), Y up
              "intensity": 0.5},               its share of the light; "sun": "none" for no sun
      "haze_distance": 800                 metres at which haze hides 63% of a colour; 0: none
    },
    "near_field_radius": 150             metres: the client's near-field distance d
  }
Unknown keys are rejected, so a typo cannot silently change a scene. Y is up, units are metres.)";
}

size_t warnImplausiblyLargeDynamicObjects(const Scene& scene, const std::string& where) {
  size_t count = 0;
  for (const Object& o : scene.objects) {
    if (!o.dynamic || o.bounds.empty()) continue;
    const double height = double(o.bounds.extent().y);
    if (!(height > kMaxPlausibleDynamicHeight)) continue;
    ++count;
    spdlog::warn(
        "{}: dynamic object '{}' is {:.1f} m tall, more than the {:.0f} m plausible for an avatar, "
        "animal or vehicle; if the file is not in metres, give it a \"scale\" in a scene manifest "
        "(e.g. \"scale\": 0.01 for centimetres; see vistream-scene info --help)",
        where, o.name, height, kMaxPlausibleDynamicHeight);
  }
  return count;
}

void checkRadianceHeader(const std::filesystem::path& path, const std::string& where) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throwInputError(InputErrorCode::BadFile, "{}: {}: cannot open it", where, path.string());
  std::string first(64, '\0');
  in.read(first.data(), std::streamsize(first.size()));
  first.resize(size_t(in.gcount()));
  first = first.substr(0, first.find('\n'));
  if (first.rfind("#?RADIANCE", 0) != 0 && first.rfind("#?RGBE", 0) != 0)
    throwInputError(
        InputErrorCode::Unsupported,
        "{}: {} is not a Radiance HDR image (its first line must start with #?RADIANCE or "
        "#?RGBE)",
        where, path.string());
}

void appendScene(Scene& scene, Scene part) {
  if (scene.objects.empty() && scene.faceCount == 0) {
    const std::string name = scene.name;
    const Environment env = scene.environment;
    scene = std::move(part);
    if (!name.empty()) scene.name = name;
    scene.environment = env;
    return;
  }
  // New common origin: the centre of both file-space bounds.
  Box3d all = scene.fileBounds();
  all.extend(part.fileBounds());
  const glm::dvec3 origin = all.empty() ? scene.origin : glm::floor(all.center());
  auto rebase = [&](Scene& s) {
    const glm::dvec3 shift = s.origin - origin;
    for (Object& o : s.objects)
      for (glm::vec3& p : o.mesh.positions) p = glm::vec3(glm::dvec3(p) + shift);
    s.origin = origin;
  };
  rebase(scene);
  rebase(part);
  const uint32_t faceOffset = scene.faceCount;
  const uint32_t materialOffset = uint32_t(scene.materials.size());
  const int32_t skinOffset = int32_t(scene.skins.size());
  const int32_t nodeOffset = int32_t(scene.nodes.size());
  for (Material& m : part.materials) scene.materials.push_back(std::move(m));
  for (Node n : part.nodes) {
    if (n.parent >= 0) n.parent += nodeOffset;
    scene.nodes.push_back(std::move(n));
  }
  for (Skin s : part.skins) {
    for (int32_t& j : s.joints) j += nodeOffset;
    scene.skins.push_back(std::move(s));
  }
  for (Animation a : part.animations) {
    for (auto& c : a.channels) c.node += nodeOffset;
    scene.animations.push_back(std::move(a));
  }
  for (Object& o : part.objects) {
    for (uint32_t& f : o.mesh.faceIds) f += faceOffset;
    for (uint32_t& m : o.mesh.materials) m += materialOffset;
    if (o.skin >= 0) o.skin += skinOffset;
    scene.objects.push_back(std::move(o));
  }
  for (auto& s : part.sources) scene.sources.push_back(std::move(s));
  for (auto& w : part.diagnostics.warnings) scene.diagnostics.warnings.push_back(std::move(w));
  scene.faceCount = faceOffset + part.faceCount;
  finalizeScene(scene);
}

Scene loadManifest(const std::filesystem::path& path, const SceneLimits& limits) {
  const std::string file = path.string();
  const std::string text = readSceneFile(path, limits);
  checkJsonNesting(text, file);
  json j;
  try {
    j = json::parse(text);
  } catch (const json::parse_error& e) {
    throwInputError("{}: not valid JSON: {}", file, e.what());
  }
  if (!j.is_object()) throwInputError("{}: the manifest must be a JSON object", file);
  rejectUnknownKeys(j, {"name", "geometry", "environment", "near_field_radius"}, file);

  Scene scene;
  if (j.contains("name") && !j["name"].is_string())
    throwInputError("{}: 'name' must be a string", file);
  scene.name = j.contains("name") ? j["name"].get<std::string>() : path.stem().string();
  const std::filesystem::path dir = path.parent_path();

  if (j.contains("near_field_radius")) {
    const json& r = j["near_field_radius"];
    if (!r.is_number() || !(r.get<double>() > 0.0))
      throwInputError("{}: near_field_radius must be a positive number", file);
    scene.environment.nearFieldRadius = r.get<float>();
  }
  if (j.contains("environment")) {
    const json& e = j["environment"];
    const std::string where = file + ": environment";
    if (!e.is_object()) throwInputError("{}: must be an object", where);
    rejectUnknownKeys(e, {"hdr", "sky", "sky_color", "sun", "haze_distance"}, where);
    if (e.contains("hdr")) {
      if (!e["hdr"].is_string()) throwInputError("{}.hdr: must be a path", where);
      scene.environment.hdrImage = dir / e["hdr"].get<std::string>();
      std::error_code ec;
      if (!std::filesystem::exists(scene.environment.hdrImage, ec))
        throwInputError("{}.hdr: {}: no such file", where, scene.environment.hdrImage.string());
      checkRadianceHeader(scene.environment.hdrImage, where + ".hdr");
    }
    if (e.contains("sky")) {
      const std::string sky = e["sky"].is_string() ? e["sky"].get<std::string>() : "";
      if (sky == "auto")
        scene.environment.sky = SkyMode::Auto;
      else if (sky == "open")
        scene.environment.sky = SkyMode::Open;
      else if (sky == "none")
        scene.environment.sky = SkyMode::None;
      else
        throwInputError("{}.sky: expected \"auto\", \"open\" or \"none\"", where);
    }
    if (e.contains("sky_color"))
      scene.environment.skyColor = glm::vec3(readVec3(e["sky_color"], where + ".sky_color"));
    if (e.contains("sun")) {
      const json& sun = e["sun"];
      if (sun.is_string() && sun.get<std::string>() == "none") {
        scene.environment.sunIntensity = 0.0f;
      } else if (sun.is_object()) {
        rejectUnknownKeys(sun, {"direction", "intensity"}, where + ".sun");
        if (sun.contains("direction")) {
          const glm::dvec3 d = readVec3(sun["direction"], where + ".sun.direction");
          if (!(glm::length(d) > 1e-9))
            throwInputError("{}.sun.direction: must not be zero", where);
          scene.environment.sunDirection = glm::vec3(glm::normalize(d));
        }
        if (sun.contains("intensity")) {
          const json& k = sun["intensity"];
          if (!k.is_number() || !(k.get<double>() >= 0.0 && k.get<double>() <= 10.0))
            throwInputError("{}.sun.intensity: expected a number in [0, 10]", where);
          scene.environment.sunIntensity = k.get<float>();
        }
      } else {
        throwInputError(
            "{}.sun: expected {{\"direction\": [x, y, z], \"intensity\": k}} or \"none\"", where);
      }
    }
    if (e.contains("haze_distance")) {
      const json& h = e["haze_distance"];
      if (!h.is_number() || !(h.get<double>() >= 0.0 && h.get<double>() <= 1e7))
        throwInputError("{}.haze_distance: expected metres in [0, 1e7] (0: no haze)", where);
      scene.environment.hazeDistance = h.get<float>();
    }
  }

  if (!j.contains("geometry") || !j["geometry"].is_array() || j["geometry"].empty())
    throwInputError("{}: 'geometry' must be a non-empty array of files", file);
  const Environment env = scene.environment;
  size_t index = 0;
  for (const json& g : j["geometry"]) {
    const std::string where = fmt::format("{}: geometry[{}]", file, index++);
    std::string name, relative;
    bool dynamic = false;
    glm::dvec3 translate(0.0);
    double scale = 1.0;
    if (g.is_string()) {
      relative = g.get<std::string>();
    } else if (g.is_object()) {
      rejectUnknownKeys(g, {"file", "dynamic", "name", "translate", "scale"}, where);
      if (!g.contains("file") || !g["file"].is_string())
        throwInputError("{}: needs a 'file' path", where);
      relative = g["file"].get<std::string>();
      if (g.contains("dynamic")) {
        if (!g["dynamic"].is_boolean()) throwInputError("{}.dynamic: must be true or false", where);
        dynamic = g["dynamic"].get<bool>();
      }
      if (g.contains("name")) {
        if (!g["name"].is_string()) throwInputError("{}.name: must be a string", where);
        name = g["name"].get<std::string>();
      }
      if (g.contains("translate")) translate = readVec3(g["translate"], where + ".translate");
      if (g.contains("scale")) {
        if (!g["scale"].is_number() || !(g["scale"].get<double>() > 0.0))
          throwInputError("{}.scale: must be a positive number", where);
        scale = g["scale"].get<double>();
      }
    } else {
      throwInputError("{}: expected a path or an object", where);
    }
    const std::filesystem::path geomPath = dir / relative;
    std::string ext = geomPath.extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (ext == ".json") throwInputError("{}: manifests cannot include manifests", where);
    // The part may have what the parts before it left of the triangle limit.
    const uint64_t before = scene.triangleCount();
    SceneLimits partLimits = limits;
    partLimits.maxTriangles = triangleLimit(limits) - std::min(before, triangleLimit(limits));
    Scene part;
    try {
      part = loadScene(geomPath, partLimits);
    } catch (const SceneLimitError& e) {
      throw SceneLimitError(
          fmt::format("{}: {} (the scene's limit is {} triangles and the files before this one "
                      "have {})",
                      where, e.what(), triangleLimit(limits), before),
          e.found, e.limit);
    }
    if (scale != 1.0 || translate != glm::dvec3(0.0)) {
      // Place the part: p_file' = p_file * scale + translate, kept in double.
      const glm::dvec3 newOrigin = part.origin * scale + translate;
      for (Object& o : part.objects)
        for (glm::vec3& p : o.mesh.positions) p = glm::vec3(glm::dvec3(p) * scale);
      part.origin = newOrigin;
      finalizeScene(part);
    }
    for (Object& o : part.objects) {
      if (dynamic) o.dynamic = true;
      if (!name.empty()) o.name = name + "/" + o.name;
    }
    warnImplausiblyLargeDynamicObjects(part, fmt::format("{} ({})", where, geomPath.string()));
    appendScene(scene, std::move(part));
    // Scaling, and re-expressing every part relative to one origin, can push
    // a position out of float range although each file was fine on its own.
    for (const Object& o : scene.objects)
      for (const glm::vec3& p : o.mesh.positions)
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
          throwInputError(
              "{}: placing {} puts object '{}' too far from the scene's local "
              "origin to store in single precision",
              where, geomPath.string(), o.name);
  }
  scene.environment = env;
  return scene;
}

}  // namespace vistream
