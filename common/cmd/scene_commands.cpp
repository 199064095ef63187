#include "common/cmd/scene_commands.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>

#include "common/cmd/cli.h"
#include "common/core/error.h"
#include "common/core/parse.h"
#include "common/core/timer.h"
#include "common/generate/generate.h"
#include "common/generate/path.h"
#include "common/generate/scene_spec.h"
#include "common/light/lighting.h"
#include "common/raycast/ray_query.h"
#include "common/raycast/sampled_visibility.h"
#include "common/scene/manifest.h"
#include "common/world/effects.h"
#include "common/world/sealed_surface.h"
#include "common/world/static_world.h"

namespace vistream {
namespace {

using nlohmann::json;

json boxJson(const Box3d& b) {
  return json{{"min", {b.lo.x, b.lo.y, b.lo.z}}, {"max", {b.hi.x, b.hi.y, b.hi.z}}};
}

void printRow(const std::string& key, const std::string& value) {
  fmt::print("  {:<28} {}\n", key, value);
}

int cmdGenerate(const std::string& type, const std::string& preset, uint64_t seed,
                const std::string& out, bool asJson) {
  std::string chosen = type;
  if (type == "city")
    chosen = preset.empty() ? "city1" : preset;  // --preset is checked at parse time
  else if (!preset.empty())
    throwInputError("--preset applies to 'city' only, not '{}'", type);
  const auto& types = sceneTypes();
  if (std::find(types.begin(), types.end(), chosen) == types.end())
    throwInputError("generate: unknown scene type '{}': expected city or one of {}", chosen,
                    fmt::join(types, ", "));
  Stopwatch clock;
  const PolygonScene polygons = generate(chosen, seed);
  const double genMs = clock.ms();
  clock.reset();
  writeObj(polygons, out);
  const double writeMs = clock.ms();
  const Scene scene = toScene(polygons);
  const Box3d b = scene.fileBounds();
  if (asJson) {
    std::cout << json{{"type", chosen},
                      {"seed", seed},
                      {"out", out},
                      {"objects", scene.objects.size()},
                      {"faces", scene.faceCount},
                      {"triangles", scene.triangleCount()},
                      {"bounds", boxJson(b)},
                      {"generate_ms", genMs},
                      {"write_ms", writeMs}}
                     .dump(2)
              << "\n";
  } else {
    fmt::print("generated {} (seed {}) -> {}\n", chosen, seed, out);
    printRow("objects", fmt::format("{}", scene.objects.size()));
    printRow("faces", fmt::format("{}", scene.faceCount));
    printRow("triangles", fmt::format("{}", scene.triangleCount()));
    printRow("size (m)",
             fmt::format("{:.1f} x {:.1f} x {:.1f}", b.extent().x, b.extent().y, b.extent().z));
    printRow("generate / write (ms)", fmt::format("{:.1f} / {:.1f}", genMs, writeMs));
  }
  return 0;
}

// The components of the static geometry by class (solids.h), for `info`.
json solidsJson(const SolidCensus& c) {
  json out = json::object();
  for (size_t k = 0; k < kSolidClassCount; ++k)
    out[solidClassName(SolidClass(k))] = {{"components", c.components[k]}, {"faces", c.faces[k]}};
  return out;
}

std::string solidsRow(const SolidCensus& c) {
  std::string out;
  for (size_t k = 0; k < kSolidClassCount; ++k)
    out += fmt::format("{}{} {} ({} faces)", k ? ", " : "", c.components[k],
                       solidClassName(SolidClass(k)), c.faces[k]);
  return out;
}

int cmdInfo(const std::string& spec, const SceneLimits& limits, const GroundChoice& ground,
            bool asJson) {
  Stopwatch clock;
  const Scene scene = openScene(spec, limits);
  const double loadMs = clock.ms();
  StaticWorldOptions worldOptions;
  worldOptions.ground = ground;
  const StaticWorld world = buildStaticWorld(scene, worldOptions);
  const FreeSpace& fs = world.freeSpace;
  const SolidCensus solids = world.solids.census();
  const SceneEffects effects = decideEffects(scene, *world.rays, fs);
  const Box3d b = scene.fileBounds();
  size_t dynamicTris = 0;
  for (const Object& o : scene.objects)
    if (o.dynamic) dynamicTris += o.mesh.triangleCount();

  if (asJson) {
    json objects = json::array();
    for (const Object& o : scene.objects)
      objects.push_back(
          {{"name", o.name}, {"triangles", o.mesh.triangleCount()}, {"dynamic", o.dynamic}});
    json decisions = json::array();
    for (const auto& d : effects.decisions)
      decisions.push_back({{"effect", d.effect}, {"enabled", d.enabled}, {"reason", d.reason}});
    std::cout << json{{"scene", scene.name},
                      {"objects", scene.objects.size()},
                      {"dynamic_objects", scene.dynamicObjectCount()},
                      {"faces", scene.faceCount},
                      {"triangles", scene.triangleCount()},
                      {"degenerate_triangles", scene.diagnostics.degenerateTriangles},
                      {"bounds", boxJson(b)},
                      {"local_origin", {scene.origin.x, scene.origin.y, scene.origin.z}},
                      {"materials", scene.materials.size()},
                      {"skins", scene.skins.size()},
                      {"animations", scene.animations.size()},
                      {"free_space",
                       {{"cell_size", fs.cellSize()},
                        {"walkable_columns", fs.walkableCount()},
                        {"open_sky_fraction", effects.openSkyFraction},
                        {"empty_reason", fs.emptyReason()}}},
                      {"ground",
                       {{"assumed", world.ground.y.has_value()},
                        {"y", world.ground.y ? json(scene.origin.y + double(*world.ground.y))
                                             : json(nullptr)},
                        {"bare_footprint", world.ground.bareFootprint},
                        {"why", world.ground.why}}},
                      {"solids", solidsJson(solids)},
                      {"sealed_solids",
                       {{"solids", world.solids.sealedCount()},
                        {"triangles", world.solids.sealedTriangles()},
                        {"weld_tolerance_m", SolidsOptions{}.weldTolerance}}},
                      {"effects", decisions},
                      {"object_list", objects},
                      {"load_ms", loadMs}}
                     .dump(2)
              << "\n";
    return 0;
  }
  fmt::print("scene {}\n", scene.name);
  // Say what each count is: "0 dynamic, 0 triangles" read as an empty scene.
  printRow("objects", fmt::format("{} ({} static, {} dynamic)", scene.objects.size(),
                                  scene.objects.size() - scene.dynamicObjectCount(),
                                  scene.dynamicObjectCount()));
  if (scene.dynamicObjectCount() > 0)
    printRow("triangles of dynamic objects", fmt::format("{}", dynamicTris));
  printRow("faces", fmt::format("{}", scene.faceCount));
  printRow("triangles", fmt::format("{}", scene.triangleCount()));
  printRow("degenerate triangles", fmt::format("{}", scene.diagnostics.degenerateTriangles));
  printRow("bounds min", fmt::format("{:.3f}, {:.3f}, {:.3f}", b.lo.x, b.lo.y, b.lo.z));
  printRow("bounds max", fmt::format("{:.3f}, {:.3f}, {:.3f}", b.hi.x, b.hi.y, b.hi.z));
  printRow("size (m)",
           fmt::format("{:.1f} x {:.1f} x {:.1f}", b.extent().x, b.extent().y, b.extent().z));
  printRow("materials / skins / anims", fmt::format("{} / {} / {}", scene.materials.size(),
                                                    scene.skins.size(), scene.animations.size()));
  printRow("free space", fmt::format("{} columns of {:.2f} m", fs.walkableCount(), fs.cellSize()));
  if (fs.walkableCount() == 0) printRow("no free space because", fs.emptyReason());
  printRow("ground", world.ground.why);
  printRow("components", solidsRow(solids));
  printRow("sealed solids",
           fmt::format("{} holding {} of {} triangles (welded within {:g} cm, T-junctions cut)",
                       world.solids.sealedCount(), world.solids.sealedTriangles(),
                       scene.triangleCount(), 100.0 * SolidsOptions{}.weldTolerance));
  printRow("load time (ms)", fmt::format("{:.1f}", loadMs));
  fmt::print("effects the scene calls for:\n");
  for (const auto& d : effects.decisions)
    fmt::print("  {:<24} {:<4} {}\n", d.effect, d.enabled ? "on" : "off", d.reason);
  return 0;
}

int cmdPath(const std::string& spec, const SceneLimits& limits, const GroundChoice& ground,
            const PathOptions& options, const std::string& out) {
  // The options are range-checked at parse time.
  const Scene scene = openScene(spec, limits);
  StaticWorldOptions worldOptions;
  worldOptions.ground = ground;
  const StaticWorld world = buildStaticWorld(scene, worldOptions);
  const auto samples = generatePath(scene, world.freeSpace, options);
  writePath(samples, out);
  spdlog::info("wrote {} frames ({:.1f} s at {:.2f} m/s) to {}", samples.size(), samples.back().t,
               kWalkingSpeed * options.speed, out);
  return 0;
}

int cmdVisible(const std::string& spec, const SceneLimits& limits, const std::string& cellText,
               size_t points, int res, uint64_t seed, bool asJson) {
  const auto v = parseNumberList(cellText, 6, "--cell");
  if (v[0] > v[3] || v[1] > v[4] || v[2] > v[5])
    throwInputError("--cell: expected x0,y0,z0,x1,y1,z1 with x0<=x1, y0<=y1, z0<=z1, got '{}'",
                    cellText);
  // --points and --res are range-checked at parse time.
  const Scene scene = openScene(spec, limits);
  StaticWorldOptions worldOptions;
  worldOptions.parts = StaticWorldParts::Solids;
  const StaticWorld world = buildStaticWorld(scene, worldOptions);
  const Box3f cell(scene.toLocal({v[0], v[1], v[2]}), scene.toLocal({v[3], v[4], v[5]}));
  SampledVisibilityOptions options;
  options.points = points;
  options.resolution = res;
  options.seed = seed;
  options.skipViewpoint = [&](const glm::vec3& p) {
    return world.solids.unservedViewpoint(*world.rays, p);
  };
  // The surface the PVS is proved for: cracks narrower than the weld
  // tolerance closed (common/world/sealed_surface.h).
  const std::unique_ptr<RayQuery> sealed =
      makeSealedRayQuery(*world.triangles, SolidsOptions{}.weldTolerance);
  const SampledVisibility vis = sampleVisibleFaces(*sealed, *world.triangles, cell, options);
  if (asJson) {
    std::cout << json{{"faces", vis.faces},
                      {"stats",
                       {{"viewpoints", vis.viewpoints},
                        {"inside_solid", vis.insideSolid},
                        {"rays", vis.rays},
                        {"hits", vis.hits},
                        {"visible_faces", vis.faces.size()},
                        {"total_faces", scene.faceCount},
                        {"time_ms", vis.timeMs}}}}
                     .dump()
              << "\n";
  } else {
    fmt::print(
        "{} of {} faces visible from {} viewpoints ({} inside closed solids skipped), {} rays in "
        "{:.1f} "
        "ms\n",
        vis.faces.size(), scene.faceCount, vis.viewpoints, vis.insideSolid, vis.rays, vis.timeMs);
    fmt::print("{}\n", fmt::join(vis.faces, " "));
  }
  return 0;
}

// Mean and 95th percentile of the per-channel byte differences of two bakes.
std::pair<double, double> colourError(const LightingGrid& a, const LightingGrid& reference) {
  std::vector<int> d;
  d.reserve(a.colours.size());
  double sum = 0.0;
  for (size_t i = 0; i < a.colours.size(); ++i) {
    int worst = 0;
    for (int c = 0; c < 3; ++c)
      worst = std::max(worst, std::abs(int(a.colours[i][c]) - int(reference.colours[i][c])));
    d.push_back(worst);
    sum += worst;
  }
  if (d.empty()) return {0.0, 0.0};
  std::nth_element(d.begin(), d.begin() + ptrdiff_t(d.size() * 95 / 100), d.end());
  return {sum / double(d.size()), double(d[d.size() * 95 / 100])};
}

int cmdLight(const std::string& spec, const SceneLimits& limits, const LightingOptions& options,
             const std::string& benchRays, bool asJson) {
  std::vector<uint32_t> rayCounts;
  if (!benchRays.empty())
    for (double r : parseNumberList(benchRays, 0, "--bench")) {
      if (!(r >= 0.0 && r <= 65536.0 && r == std::floor(r)))
        throwInputError("--bench: ray counts must be whole numbers in 0..65536, got {}", r);
      rayCounts.push_back(uint32_t(r));
    }
  const Scene scene = openScene(spec, limits);
  const FlatTriangles tris = flattenScene(scene, /*staticOnly=*/true);
  const auto rays = makeEmbreeRayQuery(tris);
  const EnvironmentLight env = EnvironmentLight::of(scene.environment);
  LightingStats stats;
  const LightingGrid grid = bakeLighting(scene, tris, *rays, env, options, &stats, !asJson);
  json j{{"scene", scene.name},
         {"environment", env.source()},
         {"triangles", stats.triangles},
         {"points", stats.points},
         {"points_computed", stats.fullPoints},
         {"points_per_triangle", stats.triangles ? double(stats.points) / stats.triangles : 0.0},
         {"ao_rays", stats.aoRays},
         {"shadow_rays", stats.shadowRays},
         {"mean_ao", stats.meanAo},
         {"textured_materials", stats.texturedMaterials},
         {"warnings", stats.warnings},
         {"bake_s", stats.seconds},
         {"options",
          {{"spacing_m", options.spacing},
           {"max_level", options.maxLevel},
           {"tolerance", options.tolerance},
           {"ao_rays", options.aoRays},
           {"ao_distance_m", options.aoDistance},
           {"ambient", options.ambient},
           {"sun_intensity", options.sunIntensity.value_or(scene.environment.sunIntensity)}}}};
  // Accuracy against time: each ray count against the bake above as the reference.
  json bench = json::array();
  for (uint32_t n : rayCounts) {
    LightingOptions o = options;
    o.aoRays = n;
    LightingStats s;
    const LightingGrid g = bakeLighting(scene, tris, *rays, env, o, &s, false);
    const auto [mean, p95] = colourError(g, grid);
    bench.push_back(
        {{"ao_rays", n}, {"bake_s", s.seconds}, {"mean_error", mean}, {"p95_error", p95}});
  }
  if (!rayCounts.empty()) j["bench"] = bench;
  if (asJson) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  fmt::print("lighting of {} ({})\n", scene.name, env.source());
  printRow("triangles", fmt::format("{}", stats.triangles));
  printRow("lighting points",
           fmt::format("{} ({:.1f} a triangle, {:g} m apart at most {} a side)", stats.points,
                       j["points_per_triangle"].get<double>(), options.spacing, options.maxLevel));
  printRow("rays", fmt::format("{} ambient occlusion, {} shadow", stats.aoRays, stats.shadowRays));
  printRow("mean ambient occlusion", fmt::format("{:.3f}", stats.meanAo));
  printRow("textured materials", fmt::format("{}", stats.texturedMaterials));
  for (const auto& w : stats.warnings) printRow("warning", w);
  printRow("bake time (s)", fmt::format("{:.2f}", stats.seconds));
  if (!rayCounts.empty()) {
    fmt::print("accuracy against time (reference: {} rays a point; error in 8-bit levels)\n",
               options.aoRays);
    fmt::print("  {:>8} {:>10} {:>12} {:>10}\n", "ao rays", "bake s", "mean error", "p95 error");
    for (const auto& b : bench)
      fmt::print("  {:>8} {:>10.2f} {:>12.2f} {:>10.0f}\n", b["ao_rays"].get<uint32_t>(),
                 b["bake_s"].get<double>(), b["mean_error"].get<double>(),
                 b["p95_error"].get<double>());
  }
  return 0;
}

}  // namespace

int runSceneTool(int argc, char** argv) {
  CLI::App app{"vistream-scene: generate, inspect and sample scenes.\n" + sceneSpecHelp()};
  std::string logLevel;
  setUpToolApp(app, logLevel);

  auto* gen = app.add_subcommand("generate", "write a procedural scene as OBJ");
  std::string genType, preset, out;
  uint64_t seed = 1;
  bool asJson = false;
  gen->add_option("type", genType, fmt::format("city or {}", fmt::join(sceneTypes(), ", ")))
      ->required();
  gen->add_option("--preset", preset, "for 'city': city1 (dense) or city2 (sparse)")
      ->check(CLI::IsMember({"city1", "city2"}));
  gen->add_option("--seed", seed, "random seed (same seed, same scene)")
      ->check(atLeast<uint64_t>(0));
  gen->add_option("--out,-o", out, "output OBJ file")->required();
  gen->add_flag("--json", asJson, "print statistics as JSON");

  // Every subcommand that loads a scene file takes the triangle limit.
  SceneLimits limits;
  auto addSceneLimits = [&](CLI::App* sub) { addSceneLimitsOption(*sub, limits); };
  GroundChoice ground;

  auto* info =
      app.add_subcommand("info", "objects, faces, bounds and the effects a scene calls for");
  std::string scene;
  info->add_option("scene", scene, "SCENE")->required();
  info->footer(manifestFormatHelp());
  info->add_flag("--json", asJson, "one JSON object on stdout");
  addSceneLimits(info);
  addGroundOption(*info, ground);

  auto* path = app.add_subcommand("path", "generate a walkthrough path through the free space");
  PathOptions pathOptions;
  path->add_option("--scene", scene, "SCENE")->required();
  path->add_option("--speed", pathOptions.speed, "relative speed, 1.0 = walking (1.4 m/s)")
      ->check(positive())
      ->capture_default_str();
  path->add_option("--frames", pathOptions.frames, "number of frames")
      ->check(atLeast<size_t>(1))
      ->capture_default_str();
  path->add_option("--fps", pathOptions.fps, "frames per second")
      ->check(positive())
      ->capture_default_str();
  path->add_option("--seed", pathOptions.seed, "random seed")
      ->check(atLeast<uint64_t>(0))
      ->capture_default_str();
  path->add_option("--goal-radius", pathOptions.goalRadius,
                   "metres round a column in which obstacles are counted: the walk's goals lie "
                   "in the denser half (streets, not the open ground around a city; 0: anywhere)")
      ->check(nonNegative())
      ->capture_default_str();
  path->add_option("--goal-clearance", pathOptions.goalClearance,
                   "metres a goal keeps from every obstacle")
      ->check(nonNegative())
      ->capture_default_str();
  path->add_option("--out,-o", out, "output CSV (t,x,y,z,yaw_deg,pitch_deg)")->required();
  addSceneLimits(path);
  addGroundOption(*path, ground);

  auto* visible =
      app.add_subcommand("visible", "sampled ground truth: faces seen from a view cell");
  std::string cell;
  size_t points = 32;
  int res = 128;
  visible->add_option("--scene", scene, "SCENE")->required();
  visible->add_option("--cell", cell, "x0,y0,z0,x1,y1,z1 in file coordinates")->required();
  visible
      ->add_option("--points", points,
                   "viewpoints (8 corners, 6 face centres, centre, then random)")
      ->check(atLeast<size_t>(1));
  visible->add_option("--res", res, "rays per cube-map face side")->check(inRange(1, 4096));
  visible->add_option("--seed", seed, "seed for the random viewpoints")
      ->check(atLeast<uint64_t>(0));
  visible->add_flag("--json", asJson, "one JSON object on stdout: faces, stats");
  addSceneLimits(visible);

  auto* light = app.add_subcommand(
      "light", "bake the scene's prelit colours (environment, sun, ambient occlusion) and report");
  LightingOptions lighting;
  std::string benchRays;
  light->add_option("--scene", scene, "SCENE")->required();
  light->add_option("--spacing", lighting.spacing, "metres between lighting points on large faces")
      ->check(positive());
  light->add_option("--max-level", lighting.maxLevel, "most lighting points along a triangle side")
      ->check(CLI::Range(1u, 255u));
  light
      ->add_option("--tolerance", lighting.tolerance,
                   "8-bit levels a coarser grid may differ from the full one (0: keep every point)")
      ->check(CLI::Range(0.0f, 255.0f));
  light->add_option("--ao-rays", lighting.aoRays, "ambient occlusion rays a point (0: off)")
      ->check(CLI::Range(0u, 65536u));
  light
      ->add_option("--ao-distance", lighting.aoDistance,
                   "metres a ray must travel to count as open")
      ->check(positive());
  light
      ->add_option("--sun-intensity", lighting.sunIntensity,
                   "the sun's share of the light (0: no sun)")
      ->check(CLI::Range(0.0f, 10.0f));
  light->add_option("--bench", benchRays,
                    "comma-separated ray counts to bake again and compare with this bake "
                    "(accuracy against time)");
  light->add_flag("--json", asJson, "one JSON object on stdout");
  addSceneLimits(light);

  return runToolApp("vistream-scene", app, argc, argv, logLevel, [&]() -> int {
    if (*light) return cmdLight(scene, limits, lighting, benchRays, asJson);
    if (*gen) return cmdGenerate(genType, preset, seed, out, asJson);
    if (*info) return cmdInfo(scene, limits, ground, asJson);
    if (*path) return cmdPath(scene, limits, ground, pathOptions, out);
    if (*visible) return cmdVisible(scene, limits, cell, points, res, seed, asJson);
    return 2;
  });
}

}  // namespace vistream
